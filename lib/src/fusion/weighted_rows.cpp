#include "fusion/weighted_rows.h"

#include <cmath>
#include <cstring>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define AVSPLAT_WEIGHTED_ROWS_AVX2 1
#include <immintrin.h>
#endif

namespace avsplat::fusion_detail {

namespace {

// Four channels at a time, in GCC's vector extension (pairs of SSE2 registers on x86-64); each
// lane does the scalar form's multiply and add (no FMA: the library is built with
// -ffp-contract=off), so every channel gets the bits it would get alone, on every ISA.
typedef double Double4 __attribute__((vector_size(32)));
typedef float Float4 __attribute__((vector_size(16)));
typedef std::int32_t Int4 __attribute__((vector_size(16)));

// Channels [c0, c0 + 4 Q) of the weighted sum, Q accumulators of four doubles held in registers
// across the voxel's samples; each channel is summed in sample order.
template <int Q>
__attribute__((always_inline)) inline bool weighted_quads(const float* __restrict rows, std::size_t width,
                                                          const std::int32_t* __restrict ids,
                                                          const double* __restrict w, std::size_t n, double inv,
                                                          std::size_t c0, float* __restrict out) {
    Double4 a[Q];
    for (int q = 0; q < Q; ++q) a[q] = Double4{0.0, 0.0, 0.0, 0.0};
    for (std::size_t k = 0; k < n; ++k) {
        const float* r = rows + width * std::size_t(ids[k]) + c0;
        const double wk = w[k];
        const Double4 wv = {wk, wk, wk, wk};
        for (int q = 0; q < Q; ++q) {
            Float4 x;
            std::memcpy(&x, r + 4 * q, sizeof x);
            a[q] += wv * __builtin_convertvector(x, Double4);
        }
    }
    const Double4 iv = {inv, inv, inv, inv};
    // A float is finite when its exponent bits are not all ones.
    Int4 bad = {0, 0, 0, 0};
    const Int4 exponent = {0x7f800000, 0x7f800000, 0x7f800000, 0x7f800000};
    for (int q = 0; q < Q; ++q) {
        const Float4 y = __builtin_convertvector(a[q] * iv, Float4);
        std::memcpy(out + c0 + 4 * q, &y, sizeof y);
        Int4 bits;
        std::memcpy(&bits, &y, sizeof bits);
        bad |= (bits & exponent) == exponent;
    }
    return (bad[0] | bad[1] | bad[2] | bad[3]) == 0;
}

// Channels [c0, width) one at a time, in the same arithmetic as one lane of weighted_quads.
bool single_channels(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                     const double* __restrict w, std::size_t n, double inv, std::size_t c0, float* __restrict out) {
    bool ok = true;
    for (; c0 < width; ++c0) {
        double a = 0.0;
        for (std::size_t k = 0; k < n; ++k) a += w[k] * double(rows[width * std::size_t(ids[k]) + c0]);
        out[c0] = float(a * inv);
        ok &= std::isfinite(out[c0]);
    }
    return ok;
}

}  // namespace

bool weighted_rows_baseline(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                            const double* __restrict w, std::size_t n, double inv, float* __restrict out) {
    // Blocks of 32 channels (eight accumulators and the weight in registers), then 16, 8 and 4,
    // then single channels.
    bool ok = true;
    std::size_t c0 = 0;
    for (; c0 + 32 <= width; c0 += 32) ok &= weighted_quads<8>(rows, width, ids, w, n, inv, c0, out);
    if (c0 + 16 <= width) {
        ok &= weighted_quads<4>(rows, width, ids, w, n, inv, c0, out);
        c0 += 16;
    }
    if (c0 + 8 <= width) {
        ok &= weighted_quads<2>(rows, width, ids, w, n, inv, c0, out);
        c0 += 8;
    }
    if (c0 + 4 <= width) {
        ok &= weighted_quads<1>(rows, width, ids, w, n, inv, c0, out);
        c0 += 4;
    }
    return single_channels(rows, width, ids, w, n, inv, c0, out) && ok;
}

#if AVSPLAT_WEIGHTED_ROWS_AVX2

bool avx2_available() {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2");
}

// Only file-local functions are compiled for AVX2: an inline function from a header
// instantiated here could be one the linker shares with baseline code.
#pragma GCC push_options
#pragma GCC target("avx2")

namespace {

// weighted_quads with intrinsics: the same operations per lane (widen, w * x, a + that; the
// final a * inv narrowed to float with round-to-nearest), so the same bits.
template <int Q>
__attribute__((always_inline)) inline bool weighted_quads_avx2(const float* __restrict rows, std::size_t width,
                                                               const std::int32_t* __restrict ids,
                                                               const double* __restrict w, std::size_t n, double inv,
                                                               std::size_t c0, float* __restrict out) {
    __m256d a[Q];
    for (int q = 0; q < Q; ++q) a[q] = _mm256_setzero_pd();
    for (std::size_t k = 0; k < n; ++k) {
        const float* r = rows + width * std::size_t(ids[k]) + c0;
        const __m256d wv = _mm256_set1_pd(w[k]);
        for (int q = 0; q < Q; ++q) a[q] = _mm256_add_pd(a[q], _mm256_mul_pd(wv, _mm256_cvtps_pd(_mm_loadu_ps(r + 4 * q))));
    }
    const __m256d iv = _mm256_set1_pd(inv);
    const __m128i exponent = _mm_set1_epi32(0x7f800000);
    __m128i bad = _mm_setzero_si128();
    for (int q = 0; q < Q; ++q) {
        const __m128 y = _mm256_cvtpd_ps(_mm256_mul_pd(a[q], iv));
        _mm_storeu_ps(out + c0 + 4 * q, y);
        const __m128i e = _mm_and_si128(_mm_castps_si128(y), exponent);
        bad = _mm_or_si128(bad, _mm_cmpeq_epi32(e, exponent));
    }
    return _mm_testz_si128(bad, bad) != 0;
}

}  // namespace

bool weighted_rows_avx2(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                        const double* __restrict w, std::size_t n, double inv, float* __restrict out) {
    // Blocks of 56 channels: 14 accumulators, the weight and one temporary fill the 16 AVX
    // registers, so that a row of up to 56 channels (plus up to 3 single ones) is read in one
    // sweep rather than as 32 + 16 + 8; what is left after the full blocks, in one block of
    // 1 to 13 quads.
    bool ok = true;
    std::size_t c0 = 0;
    for (; c0 + 56 <= width; c0 += 56) ok &= weighted_quads_avx2<14>(rows, width, ids, w, n, inv, c0, out);
    switch ((width - c0) / 4) {
#define AVSPLAT_QUADS_CASE(Q) \
    case Q: ok &= weighted_quads_avx2<Q>(rows, width, ids, w, n, inv, c0, out); break;
        AVSPLAT_QUADS_CASE(1) AVSPLAT_QUADS_CASE(2) AVSPLAT_QUADS_CASE(3) AVSPLAT_QUADS_CASE(4)
        AVSPLAT_QUADS_CASE(5) AVSPLAT_QUADS_CASE(6) AVSPLAT_QUADS_CASE(7) AVSPLAT_QUADS_CASE(8)
        AVSPLAT_QUADS_CASE(9) AVSPLAT_QUADS_CASE(10) AVSPLAT_QUADS_CASE(11) AVSPLAT_QUADS_CASE(12)
        AVSPLAT_QUADS_CASE(13)
#undef AVSPLAT_QUADS_CASE
        default: break;
    }
    c0 += (width - c0) / 4 * 4;
    ok &= single_channels(rows, width, ids, w, n, inv, c0, out);
    return ok;
}

#pragma GCC pop_options

#else

bool avx2_available() { return false; }

bool weighted_rows_avx2(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                        const double* __restrict w, std::size_t n, double inv, float* __restrict out) {
    return weighted_rows_baseline(rows, width, ids, w, n, inv, out);
}

#endif

bool weighted_rows(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                   const double* __restrict w, std::size_t n, double inv, float* __restrict out) {
    static const bool avx2 = avx2_available();
    return avx2 ? weighted_rows_avx2(rows, width, ids, w, n, inv, out)
                : weighted_rows_baseline(rows, width, ids, w, n, inv, out);
}

}  // namespace avsplat::fusion_detail
