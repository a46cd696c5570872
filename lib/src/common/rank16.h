// Ranks of up to 16 values by counting: the place of each value in sorted order, ties by
// position, with a fixed amount of branch-free work (no data-dependent branch to mispredict).
// Used to order the few samples of a typical voxel. On x86 (SSE2) the 16 comparisons of each
// value run in four registers; the ranks are integers, so every path gives the same result.
#pragma once

#include "avsplat/common/hostdevice.h"

#include <stdint.h>

#if defined(__SSE2__) && !defined(__CUDA_ARCH__)
#include <emmintrin.h>
#define AVSPLAT_RANK16_SSE2 1
#endif

namespace avsplat {

#ifdef AVSPLAT_RANK16_SSE2
namespace rank16_detail {

/// The counting shared by both rank functions: rank[i] = #{j : before(c_j, x_i)} + #{j < i :
/// same(c_j, x_i)} for i < n, over 16 slots. load(k) gives slots k..k+3 as a register, splat(i)
/// slot i in every lane; before and same give comparison masks (-1 where true) as __m128i.
template <class Load, class Splat, class Before, class Same>
inline void rank16_sse2(int n, Load load, Splat splat, Before before, Same same, int* rank) {
    const auto c0 = load(0), c1 = load(4), c2 = load(8), c3 = load(12);
    const __m128i l0 = _mm_setr_epi32(0, 1, 2, 3), l1 = _mm_setr_epi32(4, 5, 6, 7),
                  l2 = _mm_setr_epi32(8, 9, 10, 11), l3 = _mm_setr_epi32(12, 13, 14, 15);
    for (int i = 0; i < n; ++i) {
        const auto v = splat(i);
        const __m128i at = _mm_set1_epi32(i);
        // Masks are -1 where true: adding them counts down.
        __m128i count = before(c0, v);
        count = _mm_add_epi32(count, before(c1, v));
        count = _mm_add_epi32(count, before(c2, v));
        count = _mm_add_epi32(count, before(c3, v));
        count = _mm_add_epi32(count, _mm_and_si128(same(c0, v), _mm_cmplt_epi32(l0, at)));
        count = _mm_add_epi32(count, _mm_and_si128(same(c1, v), _mm_cmplt_epi32(l1, at)));
        count = _mm_add_epi32(count, _mm_and_si128(same(c2, v), _mm_cmplt_epi32(l2, at)));
        count = _mm_add_epi32(count, _mm_and_si128(same(c3, v), _mm_cmplt_epi32(l3, at)));
        count = _mm_add_epi32(count, _mm_shuffle_epi32(count, 0x4E));
        count = _mm_add_epi32(count, _mm_shuffle_epi32(count, 0xB1));
        rank[i] = -_mm_cvtsi128_si32(count);
    }
}

}  // namespace rank16_detail
#endif

/// Place of each of x[0..n) in increasing unsigned order, ties by position: rank[i] = #{j :
/// x[j] < x[i]} + #{j < i : x[j] == x[i]}, n <= 16. x holds 16 values, padded beyond n with
/// UINT32_MAX, which must not occur among the values (float_order_key never gives it), so a
/// pad never comes before a value. Host only.
inline void rank_ascending16(const uint32_t* x, int n, int* rank) {
#ifdef AVSPLAT_RANK16_SSE2
    // Unsigned order through signed comparisons: flip the sign bits.
    const __m128i flip = _mm_set1_epi32(int(0x80000000u));
    rank16_detail::rank16_sse2(
        n, [&](int k) { return _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(x + k)), flip); },
        [&](int i) { return _mm_set1_epi32(int(x[i] ^ 0x80000000u)); },
        [](__m128i c, __m128i v) { return _mm_cmplt_epi32(c, v); },
        [](__m128i c, __m128i v) { return _mm_cmpeq_epi32(c, v); }, rank);
#else
    for (int i = 0; i < n; ++i) {
        int r = 0;
        for (int j = 0; j < 16; ++j) r += (x[j] < x[i]) + ((x[j] == x[i]) & (j < i));
        rank[i] = r;
    }
#endif
}

/// Place of each of c[0..n) in decreasing order, ties by position: rank[i] = #{j : c[j] > c[i]}
/// + #{j < i : c[j] == c[i]}, n <= 16, no NaN. c holds 16 values, padded with -inf beyond n (a
/// pad is never greater than a value, and equal pads sit after every real index, so they change
/// no rank). Floats on x86 use SSE2; other types and devices count in a plain loop.
template <class T>
AVSPLAT_HD void rank_descending16(const T* c, int n, int* rank) {
#ifdef AVSPLAT_RANK16_SSE2
    if constexpr (sizeof(T) == sizeof(float)) {
        rank16_detail::rank16_sse2(
            n, [&](int k) { return _mm_loadu_ps(c + k); }, [&](int i) { return _mm_set1_ps(c[i]); },
            [](__m128 a, __m128 v) { return _mm_castps_si128(_mm_cmpgt_ps(a, v)); },
            [](__m128 a, __m128 v) { return _mm_castps_si128(_mm_cmpeq_ps(a, v)); }, rank);
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

}  // namespace avsplat
