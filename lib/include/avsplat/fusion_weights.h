// Per-voxel weight maths of occupancy-guided voxel fusion (DESIGN.md; AVSplat supplement,
// Algorithm 2): confidence mapping, geometric consistency, reliability, temperature,
// softmax / sparsemax, trimming and entropy.
//
// Header-only AVSPLAT_HD functions templated on the scalar T, so that the CPU path, a CUDA path
// and the float64 reference used by the tests run the same source. Sums over samples are
// accumulated in double whatever T is. Array arguments hold one voxel's n >= 1 samples.
#pragma once

#include "avsplat/hostdevice.h"

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

/// How a raw confidence c becomes a logit l (the softmax input) and a probability q (for the
/// reliability term). Every mapping clamps l to [-FLT_MAX, FLT_MAX] so that it is finite.
///   Logit        any finite c:   l = c,                  q = sigmoid(c)       (default)
///   Probability  c in [0, 1]:    l = log(c) - log(1-c),  q = c
///   Positive     c >= 0 (the 1 + exp(x) confidences of VGGT / AnySplat heads):
///                                l = log(c),             q = c / (1 + c)
/// A confidence outside its mapping's domain, or NaN/Inf, is invalid.
enum class ConfidenceMapping { Logit, Probability, Positive };

/// Normalisation of the tempered logits z_i = l_i / tau into weights.
///   Softmax    w_i = exp(z_i - max z) / sum_j exp(z_j - max z)
///   Sparsemax  Euclidean projection of z onto the simplex (Martins & Astudillo 2016): weights
///              of samples more than one temperature-scaled unit below the leaders become 0.
enum class WeightFunction { Softmax, Sparsemax };

namespace fusion_weights {

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

/// Temperature tau = clip(tau0 * max(n / n_ref, eps)^(-alpha) / (1 + k_rel * (1 - r)),
/// tau_min, tau_max): crowded, reliable voxels get sharper weights.
template <class T>
AVSPLAT_HD T temperature(long long n, T r, T tau0, T alpha, T n_ref, T tau_min, T tau_max, T k_rel,
                         T eps) {
    T ratio = T(n) / n_ref;
    if (ratio < eps) ratio = eps;
    const T tau = tau0 * std::pow(ratio, -alpha) / (T(1) + k_rel * (T(1) - r));
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

/// Place of each of c[0..n) in decreasing order, ties by position: rank[i] = #{j : c[j] > c[i]}
/// + #{j < i : c[j] == c[i]}. c holds 16 values, padded with -inf beyond n (a pad is never
/// greater than a value, and equal pads sit after every real index, so they change no rank).
/// For float on x86 the 16 comparisons of each i run in four SSE2 registers; the ranks are
/// integers either way, so both paths give the same result.
template <class T>
AVSPLAT_HD void rank_descending16(const T* c, int n, int* rank) {
#ifdef AVSPLAT_FUSION_SSE2
    if constexpr (sizeof(T) == sizeof(float)) {
        const __m128 c0 = _mm_loadu_ps(c), c1 = _mm_loadu_ps(c + 4), c2 = _mm_loadu_ps(c + 8),
                     c3 = _mm_loadu_ps(c + 12);
        const __m128i l0 = _mm_setr_epi32(0, 1, 2, 3), l1 = _mm_setr_epi32(4, 5, 6, 7),
                      l2 = _mm_setr_epi32(8, 9, 10, 11), l3 = _mm_setr_epi32(12, 13, 14, 15);
        for (int i = 0; i < n; ++i) {
            const __m128 x = _mm_set1_ps(c[i]);
            const __m128i before = _mm_set1_epi32(i);
            // Comparison masks are -1 where true: subtracting them counts.
            __m128i count = _mm_castps_si128(_mm_cmpgt_ps(c0, x));
            count = _mm_add_epi32(count, _mm_castps_si128(_mm_cmpgt_ps(c1, x)));
            count = _mm_add_epi32(count, _mm_castps_si128(_mm_cmpgt_ps(c2, x)));
            count = _mm_add_epi32(count, _mm_castps_si128(_mm_cmpgt_ps(c3, x)));
            count = _mm_add_epi32(count, _mm_and_si128(_mm_castps_si128(_mm_cmpeq_ps(c0, x)), _mm_cmplt_epi32(l0, before)));
            count = _mm_add_epi32(count, _mm_and_si128(_mm_castps_si128(_mm_cmpeq_ps(c1, x)), _mm_cmplt_epi32(l1, before)));
            count = _mm_add_epi32(count, _mm_and_si128(_mm_castps_si128(_mm_cmpeq_ps(c2, x)), _mm_cmplt_epi32(l2, before)));
            count = _mm_add_epi32(count, _mm_and_si128(_mm_castps_si128(_mm_cmpeq_ps(c3, x)), _mm_cmplt_epi32(l3, before)));
            count = _mm_add_epi32(count, _mm_shuffle_epi32(count, 0x4E));
            count = _mm_add_epi32(count, _mm_shuffle_epi32(count, 0xB1));
            rank[i] = -_mm_cvtsi128_si32(count);
        }
        return;
    }
#endif
    for (int i = 0; i < n; ++i) {
        const T x = c[i];
        int r = 0;
        for (int j = 0; j < 16; ++j) r += (c[j] > x) + ((c[j] == x) & (j < i));
        rank[i] = r;
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

/// Softmax weights of the logits l[0..n) at temperature tau > 0: w_i = exp((l_i - max l) / tau)
/// / sum. The shifted logits are <= 0 and never NaN (l is finite), so every weight is finite
/// and in [0, 1], the largest logit gets exp(0) = 1 and the sum (in double) is >= 1.
template <class T>
AVSPLAT_HD void softmax_weights(const T* l, long long n, T tau, T* w) {
    T lmax = l[0];
    for (long long i = 1; i < n; ++i) lmax = l[i] > lmax ? l[i] : lmax;
    double sum = 0.0;
    for (long long i = 0; i < n; ++i) {
        w[i] = std::exp((l[i] - lmax) / tau);
        sum += double(w[i]);
    }
    const double inv = 1.0 / sum;
    for (long long i = 0; i < n; ++i) w[i] = T(double(w[i]) * inv);
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
template <class T>
AVSPLAT_HD long long trim_weights(T* w, long long n, double m, T* scratch) {
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

}  // namespace fusion_weights
}  // namespace avsplat
