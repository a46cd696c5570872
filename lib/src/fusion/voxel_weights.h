// Per-voxel weight maths of occupancy-guided voxel fusion (AVSplat supplement, Algorithm 2;
// README, "Occupancy-guided voxel fusion"): confidence mapping, geometric consistency, reliability, temperature,
// softmax / sparsemax, trimming and entropy.
//
// Header-only AVSPLAT_HD functions templated on the scalar T, so that the CPU path, a CUDA path
// and the float64 reference used by the tests run the same source. Oracles that only the tests
// use (plain softmax, the one-call trimmed softmax) live in tests/cpp/reference/. Sums over samples are
// accumulated in double whatever T is. Array arguments hold one voxel's n >= 1 samples.
#pragma once

#include "avsplat/common/hostdevice.h"
#include "avsplat/fusion/confidence.h"
#include "core/confidence_mapping.h"
#include "common/rank16.h"
#include "common/exp_poly.h"

#include <cmath>

#ifndef __CUDA_ARCH__
#include <algorithm>
#include <functional>
#endif
#if defined(__SSE2__) && !defined(__CUDA_ARCH__)
#include <emmintrin.h>
#define AVSPLAT_FUSION_SSE2 1
#endif

namespace avsplat {

namespace fusion_weights {

// The confidence mapping is the core's (core/confidence_mapping.h); fusion reads it through
// these names.
using confidence::clamp_logit;
using confidence::confidence_logit;
using confidence::confidence_probability;
using confidence::confidence_valid;
using confidence::kMaxLogit;

/// Geometric consistency g = 1 / (1 + variance / (voxel_size^2 + eps)), in (0, 1]; variance is
/// the mean squared distance E|p - mu|^2 of the voxel's samples to their mean (the sum of the
/// per-axis variances).
template <class T>
AVSPLAT_HD T geometric_consistency(T variance, T voxel_size, T eps) {
    return T(1) / (T(1) + variance / (voxel_size * voxel_size + eps));
}

/// Reliability r = clip((b_conf * mean_q + b_geo * g) / (b_conf + b_geo + eps), 0, 1).
template <class T>
AVSPLAT_HD T reliability(T mean_q, T g, T b_conf, T b_geo, T eps) {
    const T r = (b_conf * mean_q + b_geo * g) / (b_conf + b_geo + eps);
    return r < T(0) ? T(0) : (r > T(1) ? T(1) : r);
}

/// The occupancy part of the temperature, tau0 * max(n / n_ref, eps)^(-alpha): it depends on n
/// only, so a caller may tabulate it (the test reference temperature() is temperature_from_factor of it, bit for bit).
template <class T>
AVSPLAT_HD T temperature_factor(long long n, T tau0, T alpha, T n_ref, T eps) {
    T ratio = T(n) / n_ref;
    if (ratio < eps) ratio = eps;
    return tau0 * std::pow(ratio, -alpha);
}

/// clip(factor / (1 + k_rel * (1 - r)), tau_min, tau_max), factor from temperature_factor.
template <class T>
AVSPLAT_HD T temperature_from_factor(T factor, T r, T tau_min, T tau_max, T k_rel) {
    const T tau = factor / (T(1) + k_rel * (T(1) - r));
    return tau < tau_min ? tau_min : (tau > tau_max ? tau_max : tau);
}

/// Sorts a[0..n) into decreasing order by heap sort: no recursion, no allocation, no std::
/// algorithm, so it runs on a device (sort_descending's path there for large n).
template <class T>
AVSPLAT_HD void heap_sort_descending(T* a, long long n) {
    // Min-heap; repeatedly moving the minimum to the end leaves a decreasing sequence.
    auto sift_down = [a](long long root, long long end) {
        for (;;) {
            long long child = 2 * root + 1;
            if (child >= end) return;
            if (child + 1 < end && a[child + 1] < a[child]) ++child;
            if (!(a[child] < a[root])) return;
            const T t = a[root];
            a[root] = a[child];
            a[child] = t;
            root = child;
        }
    };
    for (long long i = n / 2; i-- > 0;) sift_down(i, n);
    for (long long end = n - 1; end > 0; --end) {
        const T t = a[0];
        a[0] = a[end];
        a[end] = t;
        sift_down(0, end);
    }
}

/// Sorts a[0..n) into decreasing order in place: by counting ranks for the few samples of a
/// typical voxel (no data-dependent branch to mispredict); beyond, by std::sort on the host and
/// by heap sort on a device (no recursion, no allocation). Equal values are indistinguishable,
/// so every path gives the same sequence whatever the initial order.
template <class T>
AVSPLAT_HD void sort_descending(T* a, long long n) {
    if (n <= 16) {
        // The common case: ranks by counting over 16 padded slots, a fixed amount of
        // branch-free work.
        T copy[16];
        int rank[16];
        for (int i = 0; i < 16; ++i) copy[i] = i < n ? a[i] : -T(INFINITY);
        rank_descending16(copy, int(n), rank);
        for (int i = 0; i < int(n); ++i) a[rank[i]] = copy[i];
        return;
    }
    if (n <= 32) {
        T copy[32];
        for (long long i = 0; i < n; ++i) copy[i] = a[i];
        for (int i = 0; i < int(n); ++i) {
            // Place of copy[i] in decreasing order: the larger values, then the equal ones
            // before it (two branch-free counting loops the compiler vectorises).
            const T x = copy[i];
            int rank = 0;
            for (int j = 0; j < int(n); ++j) rank += copy[j] > x;
            for (int j = 0; j < i; ++j) rank += copy[j] == x;
            a[rank] = x;
        }
        return;
    }
#ifdef __CUDA_ARCH__
    heap_sort_descending(a, n);
#else
    std::sort(a, a + n, std::greater<T>());
#endif
}

#ifdef AVSPLAT_FUSION_SSE2
/// exp(x) of four floats x <= 0 (-inf allowed) in SSE2: Cody-Waite reduction x = k ln2 + r with
/// |r| <= ln2 / 2, a degree-6 polynomial for exp(r) (Cephes' expf, within 2 ulp of the correctly
/// rounded value, exact 1 at x = 0) and the scaling by 2^k split in two factors so that results
/// in the subnormal range round once, like std::exp. Arguments below -104 give 0.
/// The renderer's blend::exp_nonpositive is the same polynomial in scalar form for CPU and CUDA
/// alike, flushing below -87; it is kept separate because a scalar loop is measurably slower
/// here (docs/benchmarks/fusion.md) and weights down to the subnormal range keep their
/// kept count.
inline __m128 exp_nonpositive_sse2(__m128 x) {
    x = _mm_max_ps(x, _mm_set1_ps(-104.f));
    const __m128i k = _mm_cvtps_epi32(_mm_mul_ps(x, _mm_set1_ps(exp_poly::kLog2e)));  // round to nearest
    const __m128 kf = _mm_cvtepi32_ps(k);
    __m128 r = _mm_sub_ps(x, _mm_mul_ps(kf, _mm_set1_ps(exp_poly::kLn2Hi)));  // exact: ln2_hi has 9 bits
    r = _mm_sub_ps(r, _mm_mul_ps(kf, _mm_set1_ps(exp_poly::kLn2Lo)));
    __m128 p = _mm_set1_ps(exp_poly::kP0);
    p = _mm_add_ps(_mm_mul_ps(p, r), _mm_set1_ps(exp_poly::kP1));
    p = _mm_add_ps(_mm_mul_ps(p, r), _mm_set1_ps(exp_poly::kP2));
    p = _mm_add_ps(_mm_mul_ps(p, r), _mm_set1_ps(exp_poly::kP3));
    p = _mm_add_ps(_mm_mul_ps(p, r), _mm_set1_ps(exp_poly::kP4));
    p = _mm_add_ps(_mm_mul_ps(p, r), _mm_set1_ps(exp_poly::kP5));
    const __m128 y = _mm_add_ps(_mm_add_ps(_mm_mul_ps(_mm_mul_ps(p, r), r), r), _mm_set1_ps(1.f));
    // 2^k = 2^k1 * 2^k2 with k1 = floor(k / 2), k2 = k - k1, both normal for k >= -150.
    const __m128i k1 = _mm_srai_epi32(k, 1), k2 = _mm_sub_epi32(k, k1);
    const __m128 s1 = _mm_castsi128_ps(_mm_slli_epi32(_mm_add_epi32(k1, _mm_set1_epi32(127)), 23));
    const __m128 s2 = _mm_castsi128_ps(_mm_slli_epi32(_mm_add_epi32(k2, _mm_set1_epi32(127)), 23));
    return _mm_mul_ps(_mm_mul_ps(y, s1), s2);
}

/// sigmoid of four finite floats: 1 / (1 + exp(-|x|)), times exp(-|x|) for negative x.
inline __m128 sigmoid_sse2(__m128 v) {
    const __m128 e = exp_nonpositive_sse2(_mm_or_ps(v, _mm_set1_ps(-0.f)));  // exp(-|v|)
    const __m128 r = _mm_div_ps(_mm_set1_ps(1.f), _mm_add_ps(_mm_set1_ps(1.f), e));
    const __m128 neg = _mm_cmplt_ps(v, _mm_setzero_ps());
    return _mm_or_ps(_mm_and_ps(neg, _mm_mul_ps(e, r)), _mm_andnot_ps(neg, r));
}

/// out[i] = four(x[i..i+4)) for i < n, four floats at a time; the last 1-3 go through a padded
/// register, so a value gives the same bits wherever it sits. out may alias x.
template <class Four>
inline void map4_sse2(const float* x, long long n, float* out, Four four) {
    long long i = 0;
    for (; i + 4 <= n; i += 4) _mm_storeu_ps(out + i, four(_mm_loadu_ps(x + i)));
    if (i < n) {
        float tail[4] = {0.f, 0.f, 0.f, 0.f};
        for (long long j = i; j < n; ++j) tail[j - i] = x[j];
        _mm_storeu_ps(tail, four(_mm_loadu_ps(tail)));
        for (long long j = i; j < n; ++j) out[j] = tail[j - i];
    }
}
#endif

/// out[i] = exp(x[i]) for x[i] <= 0 (or -inf), i < n; out may alias x. Floats on x86 run four
/// at a time in SSE2 (exp_nonpositive_sse2: within 2 ulp of std::exp, the same bits for a value
/// wherever it sits in the array); doubles and other targets use std::exp.
template <class T>
AVSPLAT_HD void exp_nonpositive(const T* x, long long n, T* out) {
#ifdef AVSPLAT_FUSION_SSE2
    if constexpr (sizeof(T) == sizeof(float)) {
        map4_sse2(x, n, out, [](__m128 v) { return exp_nonpositive_sse2(v); });
        return;
    }
#endif
    for (long long i = 0; i < n; ++i) out[i] = std::exp(x[i]);
}

/// q[i] = sigmoid(x[i]) = 1 / (1 + exp(-x[i])) for finite x, i < n, without overflow (exp of
/// -|x| only); the Logit mapping's probability, four at a time for floats on x86.
template <class T>
AVSPLAT_HD void sigmoid(const T* x, long long n, T* q) {
#ifdef AVSPLAT_FUSION_SSE2
    if constexpr (sizeof(T) == sizeof(float)) {
        map4_sse2(x, n, q, [](__m128 v) { return sigmoid_sse2(v); });
        return;
    }
#endif
    for (long long i = 0; i < n; ++i) {
        const T e = std::exp(x[i] >= T(0) ? -x[i] : x[i]);
        const T r = T(1) / (T(1) + e);
        q[i] = x[i] >= T(0) ? r : e * r;
    }
}

/// Sparsemax weights of the logits l[0..n) at temperature tau > 0: with z_i = (l_i - max l) / tau
/// sorted decreasingly, the support is the largest k with 1 + k z_(k) > sum_{j<=k} z_(j), the
/// threshold t = (sum_{j<=k} z_(j) - 1) / k and w_i = max(z_i - t, 0). scratch holds n values.
template <class T>
AVSPLAT_HD void sparsemax_weights(const T* l, long long n, T tau, T* w, T* scratch) {
    T lmax = l[0];
    for (long long i = 1; i < n; ++i) lmax = l[i] > lmax ? l[i] : lmax;
    for (long long i = 0; i < n; ++i) {
        w[i] = (l[i] - lmax) / tau;  // <= 0; -inf only for gaps beyond the scalar's range
        scratch[i] = w[i];
    }
    sort_descending(scratch, n);
    double cumsum = 0.0, support_sum = 0.0;
    long long support = 0;
    for (long long k = 0; k < n; ++k) {
        const double z = double(scratch[k]);
        cumsum += z;
        if (1.0 + double(k + 1) * z > cumsum) {
            support = k + 1;
            support_sum = cumsum;
        } else {
            break;  // z decreases: once outside, every later sample is too
        }
    }
    const double threshold = (support_sum - 1.0) / double(support);
    for (long long i = 0; i < n; ++i) {
        const double d = double(w[i]) - threshold;
        w[i] = d > 0.0 ? T(d) : T(0);
    }
}

/// Trims weights w[0..n) (non-negative, summing to 1) to mass m: sorted decreasingly, the
/// shortest prefix whose cumulative weight (summed in double) reaches m is kept, together with
/// every sample whose weight equals the last kept one (ties are kept or dropped together, so the
/// result never depends on the order of equal weights), and the kept weights are renormalised.
/// At least one sample is kept. m <= 0 or m >= 1 keeps everything. scratch holds n values.
/// Returns the number of non-zero weights afterwards.
/// When kept_mass is not null it receives the mass the kept weights had before renormalising
/// (1 when nothing is trimmed), so that log w_final = log w - log kept_mass.
template <class T>
AVSPLAT_HD long long trim_weights(T* w, long long n, double m, T* scratch, double* kept_mass = nullptr) {
    if (kept_mass) *kept_mass = 1.0;
    if (!(m > 0.0 && m < 1.0)) {
        long long nonzero = 0;
        for (long long i = 0; i < n; ++i) nonzero += w[i] > T(0);
        return nonzero;
    }
    for (long long i = 0; i < n; ++i) scratch[i] = w[i];
    sort_descending(scratch, n);
    // Walk down the sorted weights until the mass reaches m, then past the ties of the cut. The
    // leader is > 0 (softmax and sparsemax both give it a positive weight), so the cut is > 0;
    // when rounding keeps the sum below m, every positive weight is kept.
    double kept = 0.0;
    long long k = 0;
    while (k < n && scratch[k] > T(0) && kept < m) kept += double(scratch[k++]);
    const T cut = scratch[k - 1];
    while (k < n && scratch[k] == cut) kept += double(scratch[k++]);
    const double inv = 1.0 / kept;
    for (long long i = 0; i < n; ++i) w[i] = w[i] >= cut ? T(double(w[i]) * inv) : T(0);
    if (kept_mass) *kept_mass = kept;
    return k;
}

/// Entropy -sum w_i log w_i of weights w[0..n) (0 log 0 = 0), in nats: 0 for one sample, log n
/// for uniform weights.
template <class T>
AVSPLAT_HD T weight_entropy(const T* w, long long n) {
    double h = 0.0;
    for (long long i = 0; i < n; ++i) {
        // log(1) = 0 stands in for log(0): a select, not a branch on which weights were trimmed.
        const T lw = std::log(w[i] > T(0) ? w[i] : T(1));
        h -= double(w[i]) * double(lw);
    }
    return T(h > 0.0 ? h : 0.0);
}

/// The tempered, shifted logits of a softmax: z_i = (l_i - max l) / tau for i < n, tau > 0. They
/// are <= 0, and the largest is 0 (-inf only for gaps beyond the scalar's range).
template <class T>
AVSPLAT_HD void softmax_logits(const T* l, long long n, T tau, T* z) {
    T lmax = l[0];
    for (long long i = 1; i < n; ++i) lmax = l[i] > lmax ? l[i] : lmax;
    for (long long i = 0; i < n; ++i) z[i] = (l[i] - lmax) / tau;
}

/// The last step of a trimmed softmax (softmax_normalise_sorted, and the test reference): w_i = w_i / total (total =
/// the sum of the kept exponentials), and the entropy sum_{w_i > 0} w_i (log total - z_i) of the
/// result, one logarithm per call. Returns the number of non-zero weights.
template <class T>
AVSPLAT_HD long long normalise_with_entropy(T* w, const T* z, long long n, double total, T* entropy) {
    const double inv = 1.0 / total, log_total = std::log(total);
    long long kept = 0;
    double h = 0.0;
    for (long long i = 0; i < n; ++i) {
        w[i] = T(double(w[i]) * inv);
        const bool live = w[i] > T(0);
        kept += live;
        h += live ? double(w[i]) * (log_total - double(live ? z[i] : T(0))) : 0.0;
    }
    *entropy = T(h > 0.0 ? h : 0.0);
    return kept;
}

/// The rest of a trimmed softmax for exponentials already in decreasing order (as they are when the samples
/// are ordered by decreasing logit; an approximate exp may leave neighbours out of order by an
/// ulp, which this tolerates): the trimming walks the values in their given order until the
/// mass reaches m * total, the smallest value passed is the cut, and every value >= cut is kept,
/// so the result is the sorting reference's (tests/cpp/reference) without its sort. scratch is not needed.
template <class T>
AVSPLAT_HD long long softmax_normalise_sorted(T* w, const T* z, long long n, double m, T* entropy) {
    double total = 0.0;
    for (long long i = 0; i < n; ++i) total += double(w[i]);
    if (m > 0.0 && m < 1.0) {
        const double mass_kept = m * total;
        double above = 0.0;
        T cut = w[0];
        for (long long k = 0; k < n && w[k] > T(0) && above < mass_kept; ++k) {
            above += double(w[k]);
            cut = w[k] < cut ? w[k] : cut;
        }
        total = 0.0;
        for (long long i = 0; i < n; ++i) {
            w[i] = w[i] >= cut ? w[i] : T(0);
            total += double(w[i]);
        }
    }
    return normalise_with_entropy(w, z, n, total, entropy);
}

}  // namespace fusion_weights
}  // namespace avsplat
