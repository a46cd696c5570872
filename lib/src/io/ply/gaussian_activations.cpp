// Bulk decoding of opacity logits and log scales with a vectorised exp, and bulk encoding with a
// vectorised log, whose every result is proven equal to the scalar one (std::exp / std::log in
// double, rounded to float), or redone with it.
//
// Why it is exact: exp4 below is within 2^-46 of exp(x) (relative; Cody-Waite reduction to
// |r| <= 0.35 and the Taylor series to degree 11, whose remainder is below 2^-47, plus a few
// roundings of 2^-53), and glibc's exp within 0.51 ulp (2^-52). Opacity's 1 / (1 + e) and
// e / (1 + e) pass the relative error of e on, damped, plus three roundings. So the scalar path's
// double result lies within 2^-44 of ours, and when ours * (1 -+ 2^-36) round to the same float,
// rounding being monotonic, the scalar path's result rounds to that float too. Where they do not
// (about one value in 2^12), and for inputs outside [-80, 80] or NaN, the scalar function is
// called. Without AVX2 and FMA (checked at run time) every value takes the scalar function.
//
// The encoders' log4 is within 2^-46 of log(x) (relative): x = m 2^e with m in [sqrt(1/2),
// sqrt(2)), log m = 2 atanh(f) with f = (m - 1) / (m + 1), |f| <= 0.172, by its series to f^17
// (remainder below 2^-48), and e ln 2 in two parts; for e != 0, |log m| <= 0.35 < |e ln 2| / 2,
// so the sum cannot cancel. Scale: glibc's log is within 0.51 ulp, so the same relative margin
// as the decoders applies. Opacity: log(p) - log1p(-p) with 1 - p exact in double (p >= 2^-30),
// whose difference can cancel (p near 1/2): the margin there is absolute, 2^-40 (|log p| +
// |log(1 - p)|), far above both sides' errors (2^-45 of the same sum). Inputs outside the ranges
// (scale <= 0, infinite or NaN; opacity below 2^-30, 1 or above, NaN) take the scalar function.
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

// log(x) for positive, finite, normal x (every float's double is one), within 2^-46 (relative).
AVSPLAT_AVX2 inline __m256d log4(__m256d x) {
    const __m256i bits = _mm256_castpd_si256(x);
    const __m256i mantissa_mask = _mm256_set1_epi64x(0x000fffffffffffffLL);
    const __m256i one_bits = _mm256_set1_epi64x(0x3ff0000000000000LL);
    __m256d m = _mm256_castsi256_pd(_mm256_or_si256(_mm256_and_si256(bits, mantissa_mask), one_bits));  // [1, 2)
    // The biased exponent (0..2047) as a double: OR it into 2^52's mantissa and subtract.
    const __m256d two52 = _mm256_set1_pd(0x1p52);
    const __m256d biased = _mm256_sub_pd(
        _mm256_castsi256_pd(_mm256_or_si256(_mm256_srli_epi64(bits, 52), _mm256_castpd_si256(two52))), two52);
    __m256d e = _mm256_sub_pd(biased, _mm256_set1_pd(1023.0));
    const __m256d big = _mm256_cmp_pd(m, _mm256_set1_pd(0x1.6a09e667f3bcdp0), _CMP_GT_OQ);  // m > sqrt(2)
    m = _mm256_blendv_pd(m, _mm256_mul_pd(m, _mm256_set1_pd(0.5)), big);
    e = _mm256_add_pd(e, _mm256_and_pd(big, _mm256_set1_pd(1.0)));
    const __m256d one = _mm256_set1_pd(1.0);
    const __m256d f = _mm256_div_pd(_mm256_sub_pd(m, one), _mm256_add_pd(m, one));  // m - 1 is exact
    const __m256d s = _mm256_mul_pd(f, f);
    // 1 + s/3 + s^2/5 + ... + s^8/17
    __m256d p = _mm256_set1_pd(1.0 / 17.0);
    for (int k = 15; k >= 3; k -= 2) p = _mm256_fmadd_pd(p, s, _mm256_set1_pd(1.0 / k));
    p = _mm256_fmadd_pd(p, s, one);
    const __m256d log_m = _mm256_mul_pd(_mm256_add_pd(f, f), p);
    // e * kLn2Hi is exact (|e| <= 1075 has 11 bits, kLn2Hi 32).
    return _mm256_add_pd(_mm256_mul_pd(e, _mm256_set1_pd(kLn2Hi)),
                         _mm256_fmadd_pd(e, _mm256_set1_pd(kLn2Lo), log_m));
}

// Writes four values; lanes that are not in ok_range or may differ from the scalar function
// take it. lo and hi bound the scalar function's double result.
template <class Scalar>
AVSPLAT_AVX2 inline void finish_between(const float* in, float* out, __m256d y, __m256d lo, __m256d hi, int ok_range,
                                        Scalar scalar) {
    const __m128 f = _mm256_cvtpd_ps(y);
    const int same = _mm_movemask_ps(_mm_cmp_ps(_mm256_cvtpd_ps(lo), _mm256_cvtpd_ps(hi), _CMP_EQ_OQ));
    const int ok = same & ok_range;
    _mm_storeu_ps(out, f);
    if (ok != 15)
        for (int i = 0; i < 4; ++i)
            if (!(ok >> i & 1)) out[i] = scalar(in[i]);
}

AVSPLAT_AVX2 void encode_scales_avx2(const float* in, float* out, std::size_t n) {
    std::size_t i = 0;
    const __m256d lo_margin = _mm256_set1_pd(1.0 - kMargin), hi_margin = _mm256_set1_pd(1.0 + kMargin);
    for (; i + 4 <= n; i += 4) {
        const __m256d x = _mm256_cvtps_pd(_mm_loadu_ps(in + i));
        // Positive and finite (false for NaN); other lanes compute log(1) and are redone.
        const __m256d ok = _mm256_and_pd(_mm256_cmp_pd(x, _mm256_setzero_pd(), _CMP_GT_OQ),
                                         _mm256_cmp_pd(x, _mm256_set1_pd(0x1.fffffep127), _CMP_LE_OQ));
        const __m256d y = log4(_mm256_blendv_pd(_mm256_set1_pd(1.0), x, ok));
        finish_between(in + i, out + i, y, _mm256_mul_pd(y, lo_margin), _mm256_mul_pd(y, hi_margin),
                       _mm256_movemask_pd(ok), [](float s) { return encode_scale(s); });
    }
    for (; i < n; ++i) out[i] = encode_scale(in[i]);
}

AVSPLAT_AVX2 void encode_opacities_avx2(const float* in, float* out, std::size_t n) {
    std::size_t i = 0;
    const __m256d one = _mm256_set1_pd(1.0);
    for (; i + 4 <= n; i += 4) {
        const __m256d p = _mm256_cvtps_pd(_mm_loadu_ps(in + i));
        // 2^-30 <= p < 1 (false for NaN), where 1 - p is exact; other lanes compute at 1/4.
        const __m256d ok = _mm256_and_pd(_mm256_cmp_pd(p, _mm256_set1_pd(0x1p-30), _CMP_GE_OQ),
                                         _mm256_cmp_pd(p, one, _CMP_LT_OQ));
        const __m256d pc = _mm256_blendv_pd(_mm256_set1_pd(0.25), p, ok);
        const __m256d a = log4(pc), b = log4(_mm256_sub_pd(one, pc));
        const __m256d y = _mm256_sub_pd(a, b);
        const __m256d abs_sum = _mm256_sub_pd(abs4(b), a);  // |a| + |b|: both logs are negative
        const __m256d margin = _mm256_mul_pd(abs_sum, _mm256_set1_pd(0x1p-40));
        finish_between(in + i, out + i, y, _mm256_sub_pd(y, margin), _mm256_add_pd(y, margin),
                       _mm256_movemask_pd(ok), [](float q) { return encode_opacity(q); });
    }
    for (; i < n; ++i) out[i] = encode_opacity(in[i]);
}

bool has_avx2() {
    static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    return yes;
}

#endif  // AVSPLAT_ACTIVATIONS_AVX2

}  // namespace

void encode_scales(const float* in, float* out, std::size_t n) {
#ifdef AVSPLAT_ACTIVATIONS_AVX2
    if (has_avx2()) return encode_scales_avx2(in, out, n);
#endif
    for (std::size_t i = 0; i < n; ++i) out[i] = encode_scale(in[i]);
}

void encode_opacities(const float* in, float* out, std::size_t n) {
#ifdef AVSPLAT_ACTIVATIONS_AVX2
    if (has_avx2()) return encode_opacities_avx2(in, out, n);
#endif
    for (std::size_t i = 0; i < n; ++i) out[i] = encode_opacity(in[i]);
}

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
