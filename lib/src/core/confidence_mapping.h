// The maths of ConfidenceMapping (avsplat/core/confidence.h): whether a confidence is valid, and
// its logit and probability. Header-only AVSPLAT_HD functions templated on the scalar, so that
// fusion's CPU path, a CUDA path, point maps and the float64 test reference run the same source.
#pragma once

#include "avsplat/core/confidence.h"
#include "avsplat/common/hostdevice.h"

#include <cmath>

namespace avsplat::confidence {

/// Bound of a mapped logit: FLT_MAX, finite in float and double.
constexpr double kMaxLogit = 3.40282346638528859811704183484516925e38;

/// Whether c is a valid confidence for mapping m.
AVSPLAT_HD bool confidence_valid(float c, ConfidenceMapping m) {
    if (!std::isfinite(c)) return false;
    switch (m) {
        case ConfidenceMapping::Probability: return c >= 0.f && c <= 1.f;
        case ConfidenceMapping::Positive: return c >= 0.f;
        default: return true;
    }
}

template <class T>
AVSPLAT_HD T clamp_logit(T l) {
    // NaN cannot occur for valid confidences; -inf/+inf (log 0, c = 1) become the bounds.
    return l < T(-kMaxLogit) ? T(-kMaxLogit) : (l > T(kMaxLogit) ? T(kMaxLogit) : l);
}

/// Logit of a valid confidence c under mapping m (see ConfidenceMapping).
template <class T>
AVSPLAT_HD T confidence_logit(float c, ConfidenceMapping m) {
    const T x = T(c);
    switch (m) {
        case ConfidenceMapping::Probability: return clamp_logit<T>(std::log(x) - std::log1p(-x));
        case ConfidenceMapping::Positive: return clamp_logit<T>(std::log(x));
        default: return x;
    }
}

/// Probability of a valid confidence c under mapping m (see ConfidenceMapping).
template <class T>
AVSPLAT_HD T confidence_probability(float c, ConfidenceMapping m) {
    const T x = T(c);
    switch (m) {
        case ConfidenceMapping::Probability: return x;
        case ConfidenceMapping::Positive: return x / (T(1) + x);
        default: {
            // sigmoid without overflow: exp of a non-positive argument only, and a select rather
            // than a branch on the sign (random signs would mispredict).
            const T e = std::exp(x >= T(0) ? -x : x);
            const T r = T(1) / (T(1) + e);
            return x >= T(0) ? r : e * r;
        }
    }
}

}  // namespace avsplat::confidence
