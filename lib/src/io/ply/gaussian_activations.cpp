// Bulk decoding of opacity logits and log scales with a vectorised exp whose every result is
// proven equal to the scalar one (std::exp in double, rounded to float), or redone with it.
//
// Why it is exact: exp4 below is within 2^-46 of exp(x) (relative; Cody-Waite reduction to
// |r| <= 0.35 and the Taylor series to degree 11, whose remainder is below 2^-47, plus a few
// roundings of 2^-53), and glibc's exp within 0.51 ulp (2^-52). Opacity's 1 / (1 + e) and
// e / (1 + e) pass the relative error of e on, damped, plus three roundings. So the scalar path's
// double result lies within 2^-44 of ours, and when ours * (1 -+ 2^-36) round to the same float,
// rounding being monotonic, the scalar path's result rounds to that float too. Where they do not
// (about one value in 2^12), and for inputs outside [-80, 80] or NaN, the scalar function is
// called. Without AVX2 and FMA (checked at run time) every value takes the scalar function.
// tests/cpp/test_ply_fast_path.cpp holds the bulk functions to the scalar ones.
#include "io/ply/gaussian_activations.h"

#include <cstdint>
#include <cstring>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define AVSPLAT_ACTIVATIONS_AVX2 1
#endif

namespace avsplat::ply {

namespace {

#ifdef AVSPLAT_ACTIVATIONS_AVX2

constexpr double kLog2e = 0x1.71547652b82fep0;
constexpr double kLn2Hi = 0x1.62e42fee00000p-1;  // 32 significant bits: n * kLn2Hi is exact
constexpr double kLn2Lo = 0x1.a39ef35793c76p-33;
constexpr double kShift = 0x1.8p52;               // adding it rounds to an integer
constexpr double kRange = 80.0;                   // exp4's domain: no overflow, no subnormal
constexpr double kMargin = 0x1p-36;

#define AVSPLAT_AVX2 __attribute__((target("avx2,fma")))

// exp(x) for |x| <= kRange, within 2^-46 (relative).
AVSPLAT_AVX2 inline __m256d exp4(__m256d x) {
    const __m256d shift = _mm256_set1_pd(kShift);
    const __m256d t = _mm256_fmadd_pd(x, _mm256_set1_pd(kLog2e), shift);
    const __m256d n = _mm256_sub_pd(t, shift);  // x / ln 2 rounded to an integer, |n| <= 116
    __m256d r = _mm256_fnmadd_pd(n, _mm256_set1_pd(kLn2Hi), x);
    r = _mm256_fnmadd_pd(n, _mm256_set1_pd(kLn2Lo), r);
    static constexpr double kTaylor[] = {1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0, 1.0 / 40320.0,
                                         1.0 / 5040.0,     1.0 / 720.0,     1.0 / 120.0,    1.0 / 24.0,
                                         1.0 / 6.0,        0.5,             1.0,            1.0};
    __m256d p = _mm256_set1_pd(kTaylor[0]);
    for (int k = 1; k < 12; ++k) p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(kTaylor[k]));
    // 2^n from the integer in t's low bits.
    const __m256i k = _mm256_sub_epi64(_mm256_castpd_si256(t), _mm256_castpd_si256(shift));
    const __m256i e = _mm256_slli_epi64(_mm256_add_epi64(k, _mm256_set1_epi64x(1023)), 52);
    return _mm256_mul_pd(p, _mm256_castsi256_pd(e));
}

// Bit i set when lane i of y rounds to the float that every value within kMargin of it rounds to.
AVSPLAT_AVX2 inline int unambiguous(__m256d y, __m128* rounded) {
    *rounded = _mm256_cvtpd_ps(y);
    const __m128 lo = _mm256_cvtpd_ps(_mm256_mul_pd(y, _mm256_set1_pd(1.0 - kMargin)));
    const __m128 hi = _mm256_cvtpd_ps(_mm256_mul_pd(y, _mm256_set1_pd(1.0 + kMargin)));
    return _mm_movemask_ps(_mm_cmp_ps(lo, hi, _CMP_EQ_OQ));
}

// Bit i set when |x_i| <= kRange (not for NaN).
AVSPLAT_AVX2 inline int in_range(__m256d a) {
    return _mm256_movemask_pd(_mm256_cmp_pd(a, _mm256_set1_pd(kRange), _CMP_LE_OQ));
}

AVSPLAT_AVX2 inline __m256d abs4(__m256d x) { return _mm256_andnot_pd(_mm256_set1_pd(-0.0), x); }

// Decodes four values in place; lanes that may differ from the scalar function take it.
template <class Scalar>
AVSPLAT_AVX2 inline void finish(float* v, __m256d y, int ok_range, Scalar scalar) {
    __m128 f;
    const int ok = unambiguous(y, &f) & ok_range;
    float in[4];
    std::memcpy(in, v, sizeof in);
    _mm_storeu_ps(v, f);
    if (ok != 15)
        for (int i = 0; i < 4; ++i)
            if (!(ok >> i & 1)) v[i] = scalar(in[i]);
}

AVSPLAT_AVX2 void scales_avx2(float* v, std::size_t n) {
    std::size_t i = 0;
    for (; i + 4 <= n; i += 4) {
        const __m256d x = _mm256_cvtps_pd(_mm_loadu_ps(v + i));
        // NaN lanes become -kRange (max returns its second operand) and are redone.
        const __m256d xc = _mm256_min_pd(_mm256_max_pd(x, _mm256_set1_pd(-kRange)), _mm256_set1_pd(kRange));
        finish(v + i, exp4(xc), in_range(abs4(x)), [](float s) { return decode_scale(s); });
    }
    for (; i < n; ++i) v[i] = decode_scale(v[i]);
}

AVSPLAT_AVX2 void opacities_avx2(float* v, std::size_t n) {
    std::size_t i = 0;
    const __m256d one = _mm256_set1_pd(1.0);
    for (; i + 4 <= n; i += 4) {
        const __m256d l = _mm256_cvtps_pd(_mm_loadu_ps(v + i));
        const __m256d a = abs4(l);
        // e = exp(-|l|); NaN lanes become exp(-kRange) and are redone.
        const __m256d e = exp4(_mm256_sub_pd(_mm256_setzero_pd(), _mm256_min_pd(a, _mm256_set1_pd(kRange))));
        const __m256d d = _mm256_add_pd(one, e);
        const __m256d positive = _mm256_cmp_pd(l, _mm256_setzero_pd(), _CMP_GE_OQ);
        const __m256d o = _mm256_blendv_pd(_mm256_div_pd(e, d), _mm256_div_pd(one, d), positive);
        finish(v + i, o, in_range(a), [](float s) { return decode_opacity(s); });
    }
    for (; i < n; ++i) v[i] = decode_opacity(v[i]);
}

bool has_avx2() {
    static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    return yes;
}

#endif  // AVSPLAT_ACTIVATIONS_AVX2

}  // namespace

void decode_scales(float* v, std::size_t n) {
#ifdef AVSPLAT_ACTIVATIONS_AVX2
    if (has_avx2()) return scales_avx2(v, n);
#endif
    for (std::size_t i = 0; i < n; ++i) v[i] = decode_scale(v[i]);
}

void decode_opacities(float* v, std::size_t n) {
#ifdef AVSPLAT_ACTIVATIONS_AVX2
    if (has_avx2()) return opacities_avx2(v, n);
#endif
    for (std::size_t i = 0; i < n; ++i) v[i] = decode_opacity(v[i]);
}

}  // namespace avsplat::ply
