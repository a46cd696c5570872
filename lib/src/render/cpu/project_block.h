// The body of the projection stage's vector kernels (project_block_kernels.h): project_one
// (project_splats.h) for 8 Gaussians at a time, one Gaussian per lane, written with GCC vector
// types so that each line reads like the scalar code it mirrors. Included only by
// project_block_avx2.cpp and project_block_avx512.cpp, after their `#pragma GCC target`, and
// everything here is in an anonymous namespace: each file gets its own copy compiled for its ISA,
// which the linker can never share with the other or with baseline code.
//
// Identical results: + - * / and sqrt are correctly rounded in every lane as in scalar code,
// floor and ceil are exact, conversions float <-> double round to nearest like the scalar casts,
// no FMA is formed (the library is built with -ffp-contract=off), and each expression below is
// the scalar one (projection.h, project_and_shade.h, sh.h, tile_state.h) with its operations in
// the same order, the same constants and the same comparisons (ordered, so NaN fails them as in
// the scalar `if`s). A culling rule is a lane mask instead of a return: lanes culled early compute
// on (possibly non-finite) values that no kept output reads. The one libm call on the way,
// log_lower_bound's std::log for a quotient below the smallest normal float, is left to the
// scalar power_cut_scalar for the lanes that need it.
//
// Memory: the block's means, scales and rotations (24, 24 and 32 consecutive floats) are loaded
// whole and deinterleaved by blends and one permutation per column; its SH rows are loaded 8
// floats at a time and transposed through registers into one vector per coefficient (measured
// against hardware gathers, 1.7x faster: docs/benchmarks/render.md). The 16 fields of the
// 8 records are transposed back and stored as whole 64-byte records (a culled lane's record is
// written too, with values nobody reads, which project_one leaves unspecified).
#pragma once

#include "render/cpu/project_block_kernels.h"
#include "render/cpu/project_splats.h"

#include <immintrin.h>

#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // 64-byte vector arguments of inline functions

namespace avsplat::detail::cpu {
namespace {

typedef double d8 __attribute__((vector_size(64)));
typedef long long m8 __attribute__((vector_size(64)));  // comparison of d8: -1 true, 0 false
typedef double d4 __attribute__((vector_size(32)));
typedef float f8 __attribute__((vector_size(32)));
typedef int i8 __attribute__((vector_size(32)));  // comparison of f8, and int lanes
typedef unsigned u8 __attribute__((vector_size(32)));

static_assert(sizeof(SplatRecord<float>) == 64, "a float record is one 64-byte line of 16 four-byte fields");

#define AVSPLAT_LANES_INLINE inline __attribute__((always_inline))

AVSPLAT_LANES_INLINE d8 bc(double x) { return d8{x, x, x, x, x, x, x, x}; }
AVSPLAT_LANES_INLINE f8 bcf(float x) { return f8{x, x, x, x, x, x, x, x}; }
AVSPLAT_LANES_INLINE d8 to_d8(f8 x) { return __builtin_convertvector(x, d8); }
AVSPLAT_LANES_INLINE f8 to_f8(d8 x) { return __builtin_convertvector(x, f8); }
AVSPLAT_LANES_INLINE i8 to_i8(m8 m) { return __builtin_convertvector(m, i8); }

#if defined(AVSPLAT_PROJECT_AVX512)  // set by project_block_avx512.cpp (GCC does not define __AVX512F__ for a target pragma)
AVSPLAT_LANES_INLINE d8 vsqrt(d8 x) { return d8(_mm512_sqrt_pd(__m512d(x))); }
AVSPLAT_LANES_INLINE d8 vfloor(d8 x) {
    return d8(_mm512_roundscale_pd(__m512d(x), _MM_FROUND_TO_NEG_INF | _MM_FROUND_NO_EXC));
}
AVSPLAT_LANES_INLINE d8 vceil(d8 x) {
    return d8(_mm512_roundscale_pd(__m512d(x), _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC));
}
/// Truncation to int32 of values that are integers in range (others give INT_MIN, unread).
AVSPLAT_LANES_INLINE i8 vtrunc_i32(d8 x) { return i8(_mm512_cvttpd_epi32(__m512d(x))); }
#else
AVSPLAT_LANES_INLINE d4 low4(d8 x) { return __builtin_shufflevector(x, x, 0, 1, 2, 3); }
AVSPLAT_LANES_INLINE d4 high4(d8 x) { return __builtin_shufflevector(x, x, 4, 5, 6, 7); }
AVSPLAT_LANES_INLINE d8 join(d4 lo, d4 hi) { return __builtin_shufflevector(lo, hi, 0, 1, 2, 3, 4, 5, 6, 7); }
AVSPLAT_LANES_INLINE d8 vsqrt(d8 x) {
    return join(d4(_mm256_sqrt_pd(__m256d(low4(x)))), d4(_mm256_sqrt_pd(__m256d(high4(x)))));
}
AVSPLAT_LANES_INLINE d8 vfloor(d8 x) {
    return join(d4(_mm256_floor_pd(__m256d(low4(x)))), d4(_mm256_floor_pd(__m256d(high4(x)))));
}
AVSPLAT_LANES_INLINE d8 vceil(d8 x) {
    return join(d4(_mm256_ceil_pd(__m256d(low4(x)))), d4(_mm256_ceil_pd(__m256d(high4(x)))));
}
AVSPLAT_LANES_INLINE i8 vtrunc_i32(d8 x) {
    return i8(_mm256_set_m128i(_mm256_cvttpd_epi32(__m256d(high4(x))), _mm256_cvttpd_epi32(__m256d(low4(x)))));
}
#endif

/// Rows r[0..7] of an 8 x 8 matrix of floats become its columns.
AVSPLAT_LANES_INLINE void transpose8(__m256* r) {
    const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
    const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
    const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
    const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
    const __m256 s0 = _mm256_shuffle_ps(t0, t2, 0x44), s1 = _mm256_shuffle_ps(t0, t2, 0xEE);
    const __m256 s2 = _mm256_shuffle_ps(t1, t3, 0x44), s3 = _mm256_shuffle_ps(t1, t3, 0xEE);
    const __m256 s4 = _mm256_shuffle_ps(t4, t6, 0x44), s5 = _mm256_shuffle_ps(t4, t6, 0xEE);
    const __m256 s6 = _mm256_shuffle_ps(t5, t7, 0x44), s7 = _mm256_shuffle_ps(t5, t7, 0xEE);
    r[0] = _mm256_permute2f128_ps(s0, s4, 0x20);
    r[1] = _mm256_permute2f128_ps(s1, s5, 0x20);
    r[2] = _mm256_permute2f128_ps(s2, s6, 0x20);
    r[3] = _mm256_permute2f128_ps(s3, s7, 0x20);
    r[4] = _mm256_permute2f128_ps(s0, s4, 0x31);
    r[5] = _mm256_permute2f128_ps(s1, s5, 0x31);
    r[6] = _mm256_permute2f128_ps(s2, s6, 0x31);
    r[7] = _mm256_permute2f128_ps(s3, s7, 0x31);
}

/// out[j][l] = rows[l * kStride + j] for the 8 rows l and the kCount columns j: the block's rows of
/// one GaussianCloud array as one vector per column. Reads no float beyond a row's kCount (masked
/// loads for a last partial group of 8 columns), so the cloud's last row may end its array.
template <int kStride, int kCount>
AVSPLAT_LANES_INLINE void load_columns(const float* rows, f8* out) {
    for (int b = 0; b < kCount; b += 8) {
        __m256 r[8];
        if (b + 8 <= kCount) {
            for (int l = 0; l < 8; ++l) r[l] = _mm256_loadu_ps(rows + l * kStride + b);
        } else {
            const __m256i live = _mm256_cmpgt_epi32(_mm256_set1_epi32(kCount - b), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
            for (int l = 0; l < 8; ++l) r[l] = _mm256_maskload_ps(rows + l * kStride + b, live);
        }
        transpose8(r);
        for (int j = 0; j < 8 && b + j < kCount; ++j) out[b + j] = f8(r[j]);
    }
}

/// The x, y, z columns of 8 rows of 3 floats (24 consecutive floats, three loads): each column is
/// blended from the three vectors and put into row order by one permutation.
AVSPLAT_LANES_INLINE void load_rows3(const float* rows, f8* out) {
    const __m256 a = _mm256_loadu_ps(rows), b = _mm256_loadu_ps(rows + 8), c = _mm256_loadu_ps(rows + 16);
    // Column x sits at a[0, 3, 6], b[1, 4, 7], c[2, 5]; y at a[1, 4, 7], b[2, 5], c[0, 3, 6]; z at
    // a[2, 5], b[0, 3, 6], c[1, 4, 7].
    const __m256 x = _mm256_blend_ps(_mm256_blend_ps(a, b, 0x92), c, 0x24);
    const __m256 y = _mm256_blend_ps(_mm256_blend_ps(a, b, 0x24), c, 0x49);
    const __m256 z = _mm256_blend_ps(_mm256_blend_ps(a, b, 0x49), c, 0x92);
    out[0] = f8(_mm256_permutevar8x32_ps(x, _mm256_setr_epi32(0, 3, 6, 1, 4, 7, 2, 5)));
    out[1] = f8(_mm256_permutevar8x32_ps(y, _mm256_setr_epi32(1, 4, 7, 2, 5, 0, 3, 6)));
    out[2] = f8(_mm256_permutevar8x32_ps(z, _mm256_setr_epi32(2, 5, 0, 3, 6, 1, 4, 7)));
}

/// The 4 columns of 8 rows of 4 floats (32 consecutive floats, four loads).
AVSPLAT_LANES_INLINE void load_rows4(const float* rows, f8* out) {
    const __m256 r01 = _mm256_loadu_ps(rows), r23 = _mm256_loadu_ps(rows + 8);
    const __m256 r45 = _mm256_loadu_ps(rows + 16), r67 = _mm256_loadu_ps(rows + 24);
    // Per 128-bit half: rows (0, 2) and (1, 3) of the first pair of loads, (4, 6) and (5, 7) of the second.
    const __m256 lo_a = _mm256_unpacklo_ps(r01, r23), hi_a = _mm256_unpackhi_ps(r01, r23);
    const __m256 lo_b = _mm256_unpacklo_ps(r45, r67), hi_b = _mm256_unpackhi_ps(r45, r67);
    // Lanes in row order 0 2 4 6 | 1 3 5 7.
    const __m256i order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
    out[0] = f8(_mm256_permutevar8x32_ps(_mm256_shuffle_ps(lo_a, lo_b, 0x44), order));
    out[1] = f8(_mm256_permutevar8x32_ps(_mm256_shuffle_ps(lo_a, lo_b, 0xEE), order));
    out[2] = f8(_mm256_permutevar8x32_ps(_mm256_shuffle_ps(hi_a, hi_b, 0x44), order));
    out[3] = f8(_mm256_permutevar8x32_ps(_mm256_shuffle_ps(hi_a, hi_b, 0xEE), order));
}

/// The 16 four-byte fields f[k][l] of 8 records as whole records out[l].
AVSPLAT_LANES_INLINE void store_records(const f8* f, SplatRecord<float>* out) {
    __m256 lo[8], hi[8];
    for (int k = 0; k < 8; ++k) {
        lo[k] = __m256(f[k]);
        hi[k] = __m256(f[8 + k]);
    }
    transpose8(lo);
    transpose8(hi);
    for (int l = 0; l < 8; ++l) {
        float* p = reinterpret_cast<float*>(out + l);
        _mm256_storeu_ps(p, lo[l]);
        _mm256_storeu_ps(p + 8, hi[l]);
    }
}

/// ViewParams<float> with the per-view terms of project_mean_covariance evaluated once (the same
/// expressions on the same values: the same bits as the scalar code's per-Gaussian evaluation).
struct BlockView {
    double R[9], t[3];
    double fx, fy, cx, cy;
    double lim_x_pos, lim_x_neg, lim_y_pos, lim_y_neg;
    double width_last, height_last;  // T(size - 1) of pixel_span
    projection::ProjectionParams proj;
    float alpha_threshold;  // of power_cutoff, as RenderOptions' float

    BlockView(const preprocess::ViewParams<float>& v, float alpha) : proj(v.proj), alpha_threshold(alpha) {
        for (int k = 0; k < 9; ++k) R[k] = v.R[k];
        for (int k = 0; k < 3; ++k) t[k] = v.t[k];
        const projection::Intrinsics<double>& K = v.K;
        fx = K.fx;
        fy = K.fy;
        cx = K.cx;
        cy = K.cy;
        const double tan_x = 0.5 * double(K.width) / K.fx, tan_y = 0.5 * double(K.height) / K.fy;
        lim_x_pos = (double(K.width) - K.cx) / K.fx + 0.3 * tan_x;
        lim_x_neg = K.cx / K.fx + 0.3 * tan_x;
        lim_y_pos = (double(K.height) - K.cy) / K.fy + 0.3 * tan_y;
        lim_y_neg = K.cy / K.fy + 0.3 * tan_y;
        width_last = double(K.width - 1);
        height_last = double(K.height - 1);
    }
};

/// projection::is_finite on lanes.
AVSPLAT_LANES_INLINE m8 finite(d8 x) { return x - x == bc(0.0); }
AVSPLAT_LANES_INLINE i8 finite(f8 x) { return x - x == bcf(0.0f); }

/// projection::pixel_span on lanes: the mask of lanes with a span, and lo, hi as doubles.
AVSPLAT_LANES_INLINE m8 pixel_span(d8 center, d8 radius, double last, d8& lo, d8& hi) {
    d8 l = vceil(center - radius - bc(0.5));
    d8 h = vfloor(center + radius - bc(0.5));
    const m8 some = l <= h;
    l = l > bc(0.0) ? l : bc(0.0);
    h = h < bc(last) ? h : bc(last);
    lo = l;
    hi = h;
    return some & (l <= h);
}

/// sh::eval_sh<float> of degree kDegree on lanes, then project_record's + 0.5 and clamp at 0.
/// coef[j] is coefficient j of the [K][3] layout (j = 3 k + channel).
template <int kDegree>
AVSPLAT_LANES_INLINE void eval_sh_rgb(const f8* coef, f8 x, f8 y, f8 z, f8* rgb) {
    for (int c = 0; c < 3; ++c) rgb[c] = bcf(float(sh::kC0)) * coef[c];
    if constexpr (kDegree >= 1) {
        const float c1 = float(sh::kC1);
        const f8 b1[3] = {bcf(-c1) * y, bcf(c1) * z, bcf(-c1) * x};
        for (int k = 0; k < 3; ++k)
            for (int c = 0; c < 3; ++c) rgb[c] += b1[k] * coef[(1 + k) * 3 + c];
    }
    if constexpr (kDegree >= 2) {
        const f8 xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
        const f8 b2[5] = {bcf(float(1.0925484305920792)) * xy,
                          bcf(float(-1.0925484305920792)) * yz,
                          bcf(float(0.31539156525252005)) * (bcf(2.0f) * zz - xx - yy),
                          bcf(float(-1.0925484305920792)) * xz,
                          bcf(float(0.5462742152960396)) * (xx - yy)};
        for (int k = 0; k < 5; ++k)
            for (int c = 0; c < 3; ++c) rgb[c] += b2[k] * coef[(4 + k) * 3 + c];
        if constexpr (kDegree >= 3) {
            const f8 b3[7] = {bcf(float(-0.5900435899266435)) * y * (bcf(3.0f) * xx - yy),
                              bcf(float(2.890611442640554)) * xy * z,
                              bcf(float(-0.4570457994644658)) * y * (bcf(4.0f) * zz - xx - yy),
                              bcf(float(0.3731763325901154)) * z * (bcf(2.0f) * zz - bcf(3.0f) * xx - bcf(3.0f) * yy),
                              bcf(float(-0.4570457994644658)) * x * (bcf(4.0f) * zz - xx - yy),
                              bcf(float(1.445305721320277)) * z * (xx - yy),
                              bcf(float(-0.5900435899266435)) * x * (xx - bcf(3.0f) * yy)};
            for (int k = 0; k < 7; ++k)
                for (int c = 0; c < 3; ++c) rgb[c] += b3[k] * coef[(9 + k) * 3 + c];
        }
    }
    for (int c = 0; c < 3; ++c) {
        const f8 v = rgb[c] + bcf(0.5f);
        rgb[c] = v < bcf(0.0f) ? bcf(0.0f) : v;
    }
}

/// power_cutoff on lanes, for lanes whose quotient alpha_threshold / opacity is a normal float or
/// whose cut does not depend on it; `scalar` marks the other lanes (log_lower_bound's std::log).
AVSPLAT_LANES_INLINE f8 power_cut(const f8* rgb, f8 depth, f8 opacity, float alpha_threshold, i8& scalar) {
    const i8 finite_all = finite(rgb[0]) & finite(rgb[1]) & finite(rgb[2]) & finite(depth) & (opacity == opacity) &
                          (alpha_threshold > 0.0f ? i8{} - 1 : i8{});
    const i8 positive = opacity > bcf(0.0f);
    const f8 x = bcf(alpha_threshold) / opacity;
    const i8 normal = x >= bcf(FLT_MIN);
    scalar = finite_all & positive & ~normal;
    // log_lower_bound for x = m 2^e.
    const u8 bits = u8(x);
    const i8 e = i8((bits >> 23) & 0xffu) - 127;
    const f8 m = f8((bits & 0x007fffffu) | 0x3f800000u);
    const f8 t = (m - bcf(1.0f)) / (m + bcf(1.0f));
    const f8 log_lb = __builtin_convertvector(e, f8) * bcf(0.693147180559945f) +
                      (bcf(2.0f) * t + bcf(2.0f / 3.0f) * t * t * t);
    const f8 cut = log_lb - bcf(float(1e-3));
    const f8 inf = bcf(INFINITY);
    return finite_all ? (positive ? cut : inf) : -inf;
}

/// project_one for the 8 Gaussians first, first + 1, ..., first + 7 of the cloud's arrays.
template <int kDegree>
AVSPLAT_LANES_INLINE void project_block(const BlockView& v, const GaussianCloud& cloud, std::int64_t first,
                                        SplatRecord<float>* splats, std::uint64_t* keys) {
    constexpr int kSh = 3 * (kDegree + 1) * (kDegree + 1);
    const std::size_t i0 = std::size_t(first);
    f8 mean_f[3], scale_f[3], quat_f[4], coef[kSh];
    load_rows3(cloud.means.data() + 3 * i0, mean_f);
    load_rows3(cloud.scales.data() + 3 * i0, scale_f);
    load_rows4(cloud.rotations.data() + 4 * i0, quat_f);
    f8 opacity_f;
    std::memcpy(&opacity_f, cloud.opacities.data() + i0, sizeof opacity_f);

    // project_record: camera-space mean (transform_point).
    const d8 m[3] = {to_d8(mean_f[0]), to_d8(mean_f[1]), to_d8(mean_f[2])};
    d8 mean_c[3];
    for (int r = 0; r < 3; ++r)
        mean_c[r] = bc(v.R[3 * r]) * m[0] + bc(v.R[3 * r + 1]) * m[1] + bc(v.R[3 * r + 2]) * m[2] + bc(v.t[r]);

    // covariance_3d<double>.
    d8 cov[6];
    {
        const d8 qw = to_d8(quat_f[0]), qx = to_d8(quat_f[1]), qy = to_d8(quat_f[2]), qz = to_d8(quat_f[3]);
        const d8 inv = bc(1.0) / vsqrt(qw * qw + qx * qx + qy * qy + qz * qz);
        const d8 w = qw * inv, x = qx * inv, y = qy * inv, z = qz * inv;
        const d8 one = bc(1.0), two = bc(2.0);
        const d8 R[9] = {one - two * (y * y + z * z), two * (x * y - w * z), two * (x * z + w * y),
                         two * (x * y + w * z), one - two * (x * x + z * z), two * (y * z - w * x),
                         two * (x * z - w * y), two * (y * z + w * x), one - two * (x * x + y * y)};
        const d8 s[3] = {to_d8(scale_f[0]), to_d8(scale_f[1]), to_d8(scale_f[2])};
        d8 M[9];
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c) M[3 * r + c] = R[3 * r + c] * s[c];
        const int rows[6] = {0, 0, 0, 1, 1, 2}, cols[6] = {0, 1, 2, 1, 2, 2};
        for (int k = 0; k < 6; ++k) {
            const d8* a = M + 3 * rows[k];
            const d8* b = M + 3 * cols[k];
            cov[k] = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        }
    }
    // rotate_covariance with the view's R.
    d8 cov_c[6];
    {
        const d8 S[9] = {cov[0], cov[1], cov[2], cov[1], cov[3], cov[4], cov[2], cov[4], cov[5]};
        d8 RS[9];
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c)
                RS[3 * r + c] = bc(v.R[3 * r]) * S[c] + bc(v.R[3 * r + 1]) * S[3 + c] + bc(v.R[3 * r + 2]) * S[6 + c];
        const int rows[6] = {0, 0, 0, 1, 1, 2}, cols[6] = {0, 1, 2, 1, 2, 2};
        for (int k = 0; k < 6; ++k) {
            const d8* a = RS + 3 * rows[k];
            const double* b = v.R + 3 * cols[k];
            cov_c[k] = a[0] * bc(b[0]) + a[1] * bc(b[1]) + a[2] * bc(b[2]);
        }
    }

    // project_gaussian. Rule 1.
    m8 keep = (mean_c[2] >= bc(v.proj.near)) & (mean_c[2] <= bc(v.proj.far));
    // project_mean_covariance.
    d8 mean2d[2], cov2d[3];
    {
        const d8 x = mean_c[0], y = mean_c[1], z = mean_c[2];
        const d8 rz = bc(1.0) / z;
        mean2d[0] = bc(v.fx) * x * rz + bc(v.cx);
        mean2d[1] = bc(v.fy) * y * rz + bc(v.cy);
        d8 u = x * rz, w = y * rz;
        u = u < bc(-v.lim_x_neg) ? bc(-v.lim_x_neg) : (u > bc(v.lim_x_pos) ? bc(v.lim_x_pos) : u);
        w = w < bc(-v.lim_y_neg) ? bc(-v.lim_y_neg) : (w > bc(v.lim_y_pos) ? bc(v.lim_y_pos) : w);
        const d8 j00 = bc(v.fx) * rz, j02 = bc(-v.fx) * u * rz, j11 = bc(v.fy) * rz, j12 = bc(-v.fy) * w * rz;
        const d8 sxx = cov_c[0], sxy = cov_c[1], sxz = cov_c[2], syy = cov_c[3], syz = cov_c[4], szz = cov_c[5];
        const d8 a0 = j00 * sxx + j02 * sxz, a1 = j00 * sxy + j02 * syz, a2 = j00 * sxz + j02 * szz;
        const d8 b1 = j11 * syy + j12 * syz, b2 = j11 * syz + j12 * szz;
        cov2d[0] = a0 * j00 + a2 * j02;
        cov2d[1] = a1 * j11 + a2 * j12;
        cov2d[2] = b1 * j11 + b2 * j12;
    }
    // add_low_pass.
    const d8 det_orig = cov2d[0] * cov2d[2] - cov2d[1] * cov2d[1];
    cov2d[0] += bc(v.proj.low_pass);
    cov2d[2] += bc(v.proj.low_pass);
    const d8 det_blur = cov2d[0] * cov2d[2] - cov2d[1] * cov2d[1];
    const d8 ratio = det_orig / det_blur;
    const d8 compensation = (det_blur > bc(0.0)) & (ratio > bc(0.0)) ? vsqrt(ratio) : bc(0.0);
    // invert_covariance_2d (in double: the conic is double there, rounded to float when written).
    const d8 det = cov2d[0] * cov2d[2] - cov2d[1] * cov2d[1];
    keep &= (det > bc(0.0)) & finite(det) & (cov2d[0] > bc(0.0));
    const d8 inv_det = bc(1.0) / det;
    const d8 conic[3] = {cov2d[2] * inv_det, -cov2d[1] * inv_det, cov2d[0] * inv_det};
    keep &= finite(conic[0]) & finite(conic[1]) & finite(conic[2]);
    // Rule 4's opacity test.
    const d8 opacity = to_d8(opacity_f);
    const d8 alpha_max = v.proj.antialiased ? opacity * compensation : opacity;
    keep &= alpha_max >= bc(v.proj.alpha_threshold);
    // splat_radius and pixel_span.
    const d8 radius_x = bc(v.proj.extent_sigma) * vsqrt(cov2d[0]);
    const d8 radius_y = bc(v.proj.extent_sigma) * vsqrt(cov2d[2]);
    d8 x_lo, x_hi, y_lo, y_hi;
    keep &= pixel_span(mean2d[0], radius_x, v.width_last, x_lo, x_hi);
    keep &= pixel_span(mean2d[1], radius_y, v.height_last, y_lo, y_hi);

    alignas(32) long long kept[8];
    std::memcpy(kept, &keep, sizeof kept);
    int n_kept = 0;
    for (int l = 0; l < 8; ++l) n_kept += kept[l] != 0;
    if (n_kept == 0) {
        for (int l = 0; l < 8; ++l) keys[i0 + std::size_t(l)] = kCulledKey;
        return;
    }

    // The view direction and the colour.
    f8 dir[3] = {bcf(0.0f), bcf(0.0f), bcf(0.0f)};
    if constexpr (kDegree > 0) {
        d8 d[3];
        for (int c = 0; c < 3; ++c)
            d[c] = bc(v.R[c]) * mean_c[0] + bc(v.R[3 + c]) * mean_c[1] + bc(v.R[6 + c]) * mean_c[2];
        const d8 inv = bc(1.0) / vsqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (int c = 0; c < 3; ++c) dir[c] = to_f8(d[c] * inv);
    }
    load_columns<kSh, kSh>(cloud.sh.data() + i0 * std::size_t(kSh), coef);
    f8 rgb[3];
    eval_sh_rgb<kDegree>(coef, dir[0], dir[1], dir[2], rgb);

    // The record's fields, in SplatRecord<float> order (splat_record.h, tile_state.h).
    f8 f[16];
    f[0] = to_f8(mean2d[0]);
    f[1] = to_f8(mean2d[1]);
    f[2] = to_f8(conic[0]);
    f[3] = to_f8(conic[1]);
    f[4] = to_f8(conic[2]);
    f[5] = to_f8(alpha_max);
    f[6] = rgb[0];
    f[7] = rgb[1];
    f[8] = rgb[2];
    f[9] = to_f8(mean_c[2]);
    f[10] = f8(vtrunc_i32(x_lo));
    f[11] = f8(vtrunc_i32(x_hi));
    f[12] = f8(vtrunc_i32(y_lo));
    f[13] = f8(vtrunc_i32(y_hi));
    i8 scalar_cut;
    f[14] = power_cut(rgb, f[9], f[5], v.alpha_threshold, scalar_cut);
    f[15] = bcf(0.0f);
    store_records(f, splats + i0);

    // depth_index_key: tiling::depth_bits (float_order_key) of the float depth over the index.
    const u8 depth_bits = u8(f[9]);
    const u8 sign = depth_bits & 0x80000000u;
    const u8 order = sign != 0u ? ~depth_bits : (depth_bits | 0x80000000u);
    alignas(32) std::uint32_t order_lanes[8];
    alignas(32) int scalar_lanes[8];
    std::memcpy(order_lanes, &order, sizeof order_lanes);
    scalar_cut &= to_i8(keep);
    std::memcpy(scalar_lanes, &scalar_cut, sizeof scalar_lanes);
    for (int l = 0; l < 8; ++l) {
        const std::size_t i = i0 + std::size_t(l);
        keys[i] = kept[l] != 0 ? (std::uint64_t(order_lanes[l]) << 32) | std::uint64_t(std::uint32_t(i)) : kCulledKey;
        if (scalar_lanes[l] != 0) power_cut_scalar(splats[i], v.alpha_threshold);
    }
}

/// project_block over `blocks` blocks from `first`, for the cloud's SH degree.
template <int kDegree>
void project_blocks_degree(const BlockView& v, const GaussianCloud& cloud, std::int64_t first, std::int64_t blocks,
                           SplatRecord<float>* splats, std::uint64_t* keys) {
    // The SH coefficients are most of what a block reads (192 of 236 bytes a Gaussian at degree 3):
    // their lines are fetched kAhead blocks ahead, which the hardware prefetcher alone, following
    // the seven streams of a block, does not do early enough.
    constexpr int kSh = 3 * (kDegree + 1) * (kDegree + 1);
    constexpr std::int64_t kAhead = 4;
    const char* sh = reinterpret_cast<const char*>(cloud.sh.data());
    const std::int64_t n_sh_bytes = std::int64_t(cloud.sh.size() * sizeof(float));
    for (std::int64_t b = 0; b < blocks; ++b) {
        const std::int64_t ahead = (first + (b + kAhead) * kProjectLanes) * kSh * std::int64_t(sizeof(float));
        for (int line = 0; line < kSh * kProjectLanes * int(sizeof(float)); line += 64)
            if (ahead + line < n_sh_bytes) _mm_prefetch(sh + ahead + line, _MM_HINT_T0);
        project_block<kDegree>(v, cloud, first + b * kProjectLanes, splats, keys);
    }
}

inline void project_blocks(const preprocess::ViewParams<float>& view, const GaussianCloud& cloud,
                           float alpha_threshold, std::int64_t first, std::int64_t blocks,
                           SplatRecord<float>* splats, std::uint64_t* keys) {
    const BlockView v(view, alpha_threshold);
    switch (view.sh_degree) {
        case 0: return project_blocks_degree<0>(v, cloud, first, blocks, splats, keys);
        case 1: return project_blocks_degree<1>(v, cloud, first, blocks, splats, keys);
        case 2: return project_blocks_degree<2>(v, cloud, first, blocks, splats, keys);
        default: return project_blocks_degree<3>(v, cloud, first, blocks, splats, keys);
    }
}

#undef AVSPLAT_LANES_INLINE

}  // namespace
}  // namespace avsplat::detail::cpu

#pragma GCC diagnostic pop
