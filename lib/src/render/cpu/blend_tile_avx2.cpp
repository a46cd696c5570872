// The AVX2 tile kernel (blend_tile_avx2.h). What it does beyond the portable kernel's loop, none
// of which changes a result:
//   - per splat, the x-only terms of the power, (a dx) dx and b dx, are computed once for the
//     16 columns, and per row (c dy) dy once, instead of per pixel (the same operations on the
//     same values, so the same bits);
//   - two rows are taken per step, and the exponentials of their (up to four) chunks with a
//     live pixel are computed before any of them is blended, so that the dependent chains
//     overlap; a step where no live pixel of the four chunks reaches the splat's power_cut
//     (tile_state.h) is skipped before the exponentials: no pixel there could pass
//     alpha_threshold, so compositing would leave it unchanged (a chunk below the cut in a step
//     that is not skipped is blended as the portable kernel blends it); such pairs still count
//     as evaluated (RenderStats::blends);
//   - the masks live in registers and the row masks are updated from the saturation mask.
//
// Only file-local functions are compiled for AVX2 (the pragma below): a template or inline
// function from a header instantiated here would be one the linker may share with baseline
// code. Header templates used here are defined before the pragma and are only inlined into
// the AVX2 functions.
#include "render/cpu/blend_tile_avx2.h"
#include "common/exp_poly.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define AVSPLAT_AVX2_KERNEL 1
#include <immintrin.h>
#endif

namespace avsplat::detail::cpu {

#if AVSPLAT_AVX2_KERNEL

bool avx2_kernel_available() {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2");
}

#pragma GCC push_options
#pragma GCC target("avx2")

namespace {

inline __m256 splat8(float v) { return _mm256_set1_ps(v); }

/// blend::exp_nonpositive(float) on 8 lanes: the same operations in the same order.
inline __m256 exp_nonpositive8(__m256 x) {
    const __m256 lo = splat8(-87.0f);
    const __m256 in_range = _mm256_cmp_ps(x, lo, _CMP_GE_OQ);
    const __m256 nonpositive = _mm256_cmp_ps(x, _mm256_setzero_ps(), _CMP_LE_OQ);
    const __m256 xc = _mm256_blendv_ps(lo, _mm256_and_ps(nonpositive, x), in_range);
    const __m256 shifted = _mm256_add_ps(_mm256_mul_ps(xc, splat8(exp_poly::kLog2e)), splat8(exp_poly::kRoundShift));
    const __m256 n = _mm256_sub_ps(shifted, splat8(exp_poly::kRoundShift));
    __m256 r = _mm256_sub_ps(xc, _mm256_mul_ps(n, splat8(exp_poly::kLn2Hi)));
    r = _mm256_sub_ps(r, _mm256_mul_ps(n, splat8(exp_poly::kLn2Lo)));
    __m256 p = splat8(exp_poly::kP0);
    p = _mm256_add_ps(_mm256_mul_ps(p, r), splat8(exp_poly::kP1));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), splat8(exp_poly::kP2));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), splat8(exp_poly::kP3));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), splat8(exp_poly::kP4));
    p = _mm256_add_ps(_mm256_mul_ps(p, r), splat8(exp_poly::kP5));
    p = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(p, _mm256_mul_ps(r, r)), r), splat8(1.0f));
    const __m256i bits = _mm256_slli_epi32(_mm256_add_epi32(_mm256_cvttps_epi32(n), _mm256_set1_epi32(127)), 23);
    return _mm256_and_ps(in_range, _mm256_mul_ps(p, _mm256_castsi256_ps(bits)));
}

/// All lanes set where bit l of `bits` (8 bits) is set.
inline __m256 lane_mask(std::uint32_t bits) {
    const __m256i lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    const __m256i b = _mm256_and_si256(_mm256_set1_epi32(int(bits)), lane_bit);
    return _mm256_castsi256_ps(_mm256_cmpeq_epi32(b, lane_bit));
}

/// tile_write (tile_state.h) with finish_row's operations on 8 lanes: the same bits.
inline void tile_write_avx2(const TileState<float>& st, int x0, int y0, int w, int h, const BlendParams<float>& p,
                            RenderResult& out) {
    const __m256 one = splat8(1.0f), zero = _mm256_setzero_ps();
    const __m256 bg0 = splat8(p.background[0]), bg1 = splat8(p.background[1]), bg2 = splat8(p.background[2]);
    for (int r = 0; r < h; ++r) {
        FinishedRow row;
        for (int half = 0; half < kTile; half += kChunk) {
            const int k = r * kTile + half;
            const __m256 tr = _mm256_load_ps(st.transmittance + k);
            // blend::finish_pixel: rgb = sum + T background, alpha = 1 - T, depth = sum / alpha or 0.
            _mm256_store_ps(row.red + half, _mm256_add_ps(_mm256_load_ps(st.red + k), _mm256_mul_ps(tr, bg0)));
            _mm256_store_ps(row.green + half, _mm256_add_ps(_mm256_load_ps(st.green + k), _mm256_mul_ps(tr, bg1)));
            _mm256_store_ps(row.blue + half, _mm256_add_ps(_mm256_load_ps(st.blue + k), _mm256_mul_ps(tr, bg2)));
            const __m256 alpha = _mm256_sub_ps(one, tr);
            const __m256 positive = _mm256_cmp_ps(alpha, zero, _CMP_GT_OQ);
            const __m256 q = _mm256_div_ps(_mm256_load_ps(st.depth + k), _mm256_blendv_ps(one, alpha, positive));
            _mm256_store_ps(row.alpha + half, alpha);
            _mm256_store_ps(row.depth + half, _mm256_and_ps(positive, q));
        }
        copy_row_out(row, st.count + r * kTile, x0, y0 + r, w, out);
    }
}

/// The splat's constants in registers and its x-only terms for the two chunks of a row.
struct Splat8 {
    __m256 ddx_a[2];  // (a dx) dx per column
    __m256 dx_b[2];   // b dx per column
    __m256 opacity, power_cut, red, green, blue, depth;
};

template <bool kContrib>
inline std::uint64_t blend_tile_avx2_impl(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                                          const SplatRecord<float>* splats, const BlendParams<float>& p,
                                          RenderResult& out, Contribution<float>* contrib) {
    TileState<float> st;
    const int x0 = tx * kTile, y0 = ty * kTile;
    const int w = std::min(kTile, out.width - x0), h = std::min(kTile, out.height - y0);
    tile_start(st, w, h);
    std::uint32_t row_live[kTile];
    const std::uint32_t row_bits = (2u << (w - 1)) - 1u;
    for (int r = 0; r < kTile; ++r) row_live[r] = r < h ? row_bits : 0u;
    int live = w * h;
    // Pixel centres x + 0.5 of the two chunks, as blend_tile.h's px.
    const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256 px[2] = {
        _mm256_add_ps(_mm256_cvtepi32_ps(_mm256_add_epi32(_mm256_set1_epi32(x0), lane)), splat8(0.5f)),
        _mm256_add_ps(_mm256_cvtepi32_ps(_mm256_add_epi32(_mm256_set1_epi32(x0 + kChunk), lane)), splat8(0.5f))};
    const __m256 threshold = splat8(p.alpha_threshold), stop = splat8(p.transmittance_stop);
    const __m256 max_alpha = splat8(blend::max_alpha<float>()), one = splat8(1.0f), zero = _mm256_setzero_ps();
    const __m256 minus_half = splat8(-0.5f);

    constexpr std::size_t kPrefetch = 8;
    std::uint64_t evaluated = 0;
    for (std::size_t k = 0; k < n_list && live > 0; ++k) {
        if (k + kPrefetch < n_list) __builtin_prefetch(splats + list[k + kPrefetch]);
        const SplatRecord<float>& s = splats[list[k]];
        const int c0 = std::max(s.x_min - x0, 0), c1 = std::min(s.x_max - x0, kTile - 1);
        const int r0 = std::max(s.y_min - y0, 0), r1 = std::min(s.y_max - y0, kTile - 1);
        const std::uint32_t box = ((2u << c1) - 1u) & ~((1u << c0) - 1u);
        Splat8 v;
        const __m256 mx = splat8(s.mean_x), a = splat8(s.conic_a), b = splat8(s.conic_b);
        for (int c = 0; c < 2; ++c) {
            const __m256 dx = _mm256_sub_ps(px[c], mx);
            v.ddx_a[c] = _mm256_mul_ps(_mm256_mul_ps(a, dx), dx);
            v.dx_b[c] = _mm256_mul_ps(b, dx);
        }
        v.opacity = splat8(s.opacity);
        v.power_cut = splat8(s.power_cut);
        v.red = splat8(s.rgb[0]);
        v.green = splat8(s.rgb[1]);
        v.blue = splat8(s.rgb[2]);
        v.depth = splat8(s.depth);
        __m256 c_max = zero, c_sum = zero;
        for (int r = r0; r <= r1; r += 2) {
            // Rows r and r + 1 (if in the box) together: their four chunks' powers and
            // exponentials first, so that the dependent chains overlap. A chunk with no live
            // lane is left alone, as the portable kernel does; a chunk below power_cut while
            // another of the four is not is still blended: that is the portable kernel's update
            // of the chunk, which skips none.
            const std::uint32_t m0 = row_live[r] & box, m1 = r + 1 <= r1 ? row_live[r + 1] & box : 0u;
            if ((m0 | m1) == 0) continue;
            evaluated += std::uint64_t(__builtin_popcount(m0) + __builtin_popcount(m1));
            const std::uint32_t bits[4] = {m0 & 0xffu, (m0 >> kChunk) & 0xffu, m1 & 0xffu, (m1 >> kChunk) & 0xffu};
            __m256 power[4], e[4];
            unsigned pass = 0;
            for (int h2 = 0; h2 < 2; ++h2) {
                const float dy = float(y0 + r + h2) + 0.5f - s.mean_y;
                const __m256 ddy_c = splat8(s.conic_c * dy * dy), dyv = splat8(dy);
                for (int c = 0; c < 2; ++c) {
                    const int q = 2 * h2 + c;
                    // blend::gaussian_power: -0.5 ((a dx) dx + (c dy) dy) - (b dx) dy.
                    power[q] = _mm256_sub_ps(_mm256_mul_ps(minus_half, _mm256_add_ps(v.ddx_a[c], ddy_c)),
                                             _mm256_mul_ps(v.dx_b[c], dyv));
                    pass |= unsigned(_mm256_movemask_ps(_mm256_cmp_ps(power[q], v.power_cut, _CMP_GE_OQ))) & bits[q];
                }
            }
            if (pass == 0) continue;
            for (int q = 0; q < 4; ++q) e[q] = bits[q] != 0 ? exp_nonpositive8(power[q]) : zero;
            for (int q = 0; q < 4; ++q) {
                const int c = q & 1, row = r + (q >> 1);
                if (bits[q] == 0) continue;
                // blend::splat_alpha, then 0 for lanes outside the box or done.
                const __m256 clamped = _mm256_min_ps(_mm256_mul_ps(v.opacity, e[q]), max_alpha);
                const __m256 alpha = _mm256_and_ps(
                    _mm256_and_ps(lane_mask(bits[q]), _mm256_cmp_ps(power[q], zero, _CMP_LE_OQ)), clamped);
                // blend::blend_step.
                const int off = row * kTile + kChunk * c;
                const __m256 tr = _mm256_load_ps(st.transmittance + off);
                const __m256 next = _mm256_mul_ps(tr, _mm256_sub_ps(one, alpha));
                const __m256 visible = _mm256_cmp_ps(alpha, threshold, _CMP_GE_OQ);
                const __m256 saturated = _mm256_and_ps(visible, _mm256_cmp_ps(next, stop, _CMP_LT_OQ));
                const __m256 blended = _mm256_and_ps(visible, _mm256_cmp_ps(next, stop, _CMP_GE_OQ));
                const __m256 alpha_tr = _mm256_mul_ps(alpha, tr);
                const __m256 weight = _mm256_and_ps(blended, alpha_tr);
                if constexpr (kContrib) {
                    const __m256 cp = _mm256_and_ps(visible, alpha_tr);
                    c_max = _mm256_max_ps(cp, c_max);
                    c_sum = _mm256_add_ps(c_sum, cp);
                }
                _mm256_store_ps(st.red + off, _mm256_add_ps(_mm256_load_ps(st.red + off), _mm256_mul_ps(weight, v.red)));
                _mm256_store_ps(st.green + off,
                                _mm256_add_ps(_mm256_load_ps(st.green + off), _mm256_mul_ps(weight, v.green)));
                _mm256_store_ps(st.blue + off,
                                _mm256_add_ps(_mm256_load_ps(st.blue + off), _mm256_mul_ps(weight, v.blue)));
                _mm256_store_ps(st.depth + off,
                                _mm256_add_ps(_mm256_load_ps(st.depth + off), _mm256_mul_ps(weight, v.depth)));
                _mm256_store_ps(st.transmittance + off, _mm256_blendv_ps(tr, next, blended));
                __m256i* cnt = reinterpret_cast<__m256i*>(st.count + off);
                _mm256_store_si256(cnt, _mm256_sub_epi32(_mm256_load_si256(cnt), _mm256_castps_si256(blended)));
                // No branch on sat != 0 (it mispredicts): with no lane saturated both are no-ops.
                const std::uint32_t sat = unsigned(_mm256_movemask_ps(saturated));
                row_live[row] &= ~(sat << (kChunk * c));
                live -= __builtin_popcount(sat);
            }
        }
        if constexpr (kContrib) {
            LaneContribution<float> here;
            _mm256_store_ps(here.max, c_max);
            _mm256_store_ps(here.sum, c_sum);
            contrib[k] = here.combine();
        }
    }
    tile_write_avx2(st, x0, y0, w, h, p, out);
    return evaluated;
}

}  // namespace

std::uint64_t blend_tile_avx2(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                              const SplatRecord<float>* splats, const BlendParams<float>& p,
                              RenderResult& out, Contribution<float>* contrib) {
    return contrib ? blend_tile_avx2_impl<true>(tx, ty, list, n_list, splats, p, out, contrib)
                   : blend_tile_avx2_impl<false>(tx, ty, list, n_list, splats, p, out, contrib);
}

#pragma GCC pop_options

#else  // no AVX2 kernel in this build

bool avx2_kernel_available() { return false; }

std::uint64_t blend_tile_avx2(int, int, const std::uint32_t*, std::size_t, const SplatRecord<float>*,
                              const BlendParams<float>&, RenderResult&, Contribution<float>*) {
    return 0;  // never called: avx2_kernel_available() is false
}

#endif

}  // namespace avsplat::detail::cpu
