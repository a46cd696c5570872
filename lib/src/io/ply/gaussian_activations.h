// Private: the 3DGS activations of a PLY file's opacity (stored as a logit) and scale (stored as
// a log), both directions (decode for the reader, encode for the writer), one value at a time
// and in bulk.
//
// Both directions compute in double and round once to float. Decoding a float32 L is then
// correctly rounded, and the writer's L is the float nearest the exact log / logit, whose decode
// is the nearest to the value in memory that any float32 L gives (a search over neighbouring
// floats found no better L in 4 million random values). Exactness is limited by float32 on disk,
// not by the arithmetic: below 1/e there are about 4x fewer float32 logs than float32 scales,
// so not every scale can come back bit-exact. Measured (tests/cpp/test_ply.cpp): bit-exact for
// scales in [1/e, e] and opacities in [0.25, 1]; at most 8 ulp for scales in [1e-6, 1e3] and
// opacities in [1e-6, 1] (half the gap between the decodes of neighbouring floats L).
#pragma once

#include <cmath>
#include <cstddef>

namespace avsplat::ply {

/// exp(log_scale) in double, rounded to float.
inline float decode_scale(double log_scale) { return static_cast<float>(std::exp(log_scale)); }

/// The logistic function of the logit l in double (in the form that does not overflow for either
/// sign), rounded to float.
inline float decode_opacity(double l) {
    if (l >= 0.0) return static_cast<float>(1.0 / (1.0 + std::exp(-l)));
    const double e = std::exp(l);
    return static_cast<float>(e / (1.0 + e));
}

/// log(s) in double, rounded to float: what the writer stores for scale s. 0 gives -inf, which
/// decodes back to 0.
inline float encode_scale(float s) { return static_cast<float>(std::log(static_cast<double>(s))); }

/// The logit of p in double, rounded to float: what the writer stores for opacity p.
/// log(p) - log1p(-p) keeps the precision of p near both ends; 0 and 1 give -inf and +inf.
inline float encode_opacity(float p) {
    const double pd = p;
    return static_cast<float>(std::log(pd) - std::log1p(-pd));
}

/// out[i] = encode_scale(in[i]) for i < n: the same bits as the scalar function (the bulk log is
/// checked against float rounding and redone with std::log where it could differ).
void encode_scales(const float* in, float* out, std::size_t n);

/// out[i] = encode_opacity(in[i]) for i < n: the same bits as the scalar function.
void encode_opacities(const float* in, float* out, std::size_t n);

/// In place, v[i] = decode_scale(v[i]) for i < n: the same bits as the scalar function (the bulk
/// exp is checked against float rounding and redone with std::exp where it could differ).
void decode_scales(float* v, std::size_t n);

/// In place, v[i] = decode_opacity(v[i]) for i < n: the same bits as the scalar function.
void decode_opacities(float* v, std::size_t n);

}  // namespace avsplat::ply
