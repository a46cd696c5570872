// The AVX-512 tile kernel (blend_tile_avx512.h): blend_tile_avx2.cpp's method with a whole tile
// row (16 pixels) per vector. A row is skipped when none of its live pixels reaches the splat's
// power_cut, which is exact for the same reason as there. Where the portable kernel updates a
// whole 8-pixel chunk with a zero weight (pixels outside the box or done, in a chunk that has a
// live pixel), this kernel updates the same chunks and leaves the others untouched (masked
// updates), so even a non-finite colour (0 x inf = NaN) lands on the same pixels. The
// contribution sums are accumulated 8 lanes at a time in the portable kernel's order (chunk 0,
// then chunk 1 of each row). For colour only, a box at most 8 columns wide is blended two tile
// rows per vector, and a wider one two rows per step with both exponentials computed before
// either row is blended (the chains overlap); both paths are without branches on the blended
// and saturated masks, which mispredict.
//
// As in blend_tile_avx2.cpp, only file-local functions are compiled for AVX-512 (the pragma).
#include "render/cpu/blend_tile_avx512.h"
#include "common/exp_poly.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define AVSPLAT_AVX512_KERNEL 1
#include <immintrin.h>
#endif

namespace avsplat::detail::cpu {

#if AVSPLAT_AVX512_KERNEL

bool avx512_kernel_available() {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f");
}

#pragma GCC push_options
#pragma GCC target("avx512f")
// GCC 12's avx512fintrin.h passes _mm512_undefined_ps() as the unused source of its unmasked
// intrinsics and warns about it (GCC bug 105593, fixed in GCC 13).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"

namespace {

inline __m512 splat16(float v) { return _mm512_set1_ps(v); }

/// blend::exp_nonpositive(float) on 16 lanes, the same operations in the same order, for
/// x <= 0 or NaN only (the caller's alpha is 0 elsewhere, whatever this returns).
inline __m512 exp_nonpositive16(__m512 x) {
    const __m512 lo = splat16(-87.0f);
    const __mmask16 in_range = _mm512_cmp_ps_mask(x, lo, _CMP_GE_OQ);
    const __mmask16 nonpositive = _mm512_cmp_ps_mask(x, _mm512_setzero_ps(), _CMP_LE_OQ);
    const __m512 xc = _mm512_mask_mov_ps(lo, in_range, _mm512_maskz_mov_ps(nonpositive, x));
    const __m512 shifted = _mm512_add_ps(_mm512_mul_ps(xc, splat16(exp_poly::kLog2e)), splat16(exp_poly::kRoundShift));
    const __m512 n = _mm512_sub_ps(shifted, splat16(exp_poly::kRoundShift));
    __m512 r = _mm512_sub_ps(xc, _mm512_mul_ps(n, splat16(exp_poly::kLn2Hi)));
    r = _mm512_sub_ps(r, _mm512_mul_ps(n, splat16(exp_poly::kLn2Lo)));
    __m512 p = splat16(exp_poly::kP0);
    p = _mm512_add_ps(_mm512_mul_ps(p, r), splat16(exp_poly::kP1));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), splat16(exp_poly::kP2));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), splat16(exp_poly::kP3));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), splat16(exp_poly::kP4));
    p = _mm512_add_ps(_mm512_mul_ps(p, r), splat16(exp_poly::kP5));
    p = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(p, _mm512_mul_ps(r, r)), r), splat16(1.0f));
    const __m512i bits = _mm512_slli_epi32(_mm512_add_epi32(_mm512_cvttps_epi32(n), _mm512_set1_epi32(127)), 23);
    return _mm512_maskz_mov_ps(in_range, _mm512_mul_ps(p, _mm512_castsi512_ps(bits)));
}

inline __m256 low8(__m512 v) { return _mm512_castps512_ps256(v); }
inline __m256 high8(__m512 v) { return _mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(v), 1)); }

/// 8 floats at a in lanes 0-7 and 8 at b in lanes 8-15.
inline __m512 load_pair(const float* a, const float* b) {
    return _mm512_castpd_ps(_mm512_insertf64x4(_mm512_castpd256_pd512(_mm256_castps_pd(_mm256_loadu_ps(a))),
                                               _mm256_castps_pd(_mm256_loadu_ps(b)), 1));
}
inline __m512i load_pair(const std::int32_t* a, const std::int32_t* b) {
    return _mm512_castps_si512(
        load_pair(reinterpret_cast<const float*>(a), reinterpret_cast<const float*>(b)));
}
/// Lanes 0-7 to a and, when `two`, lanes 8-15 to b.
inline void store_pair(float* a, float* b, __m512 v, bool two) {
    _mm256_storeu_ps(a, low8(v));
    if (two) _mm256_storeu_ps(b, high8(v));
}
inline void store_pair(std::int32_t* a, std::int32_t* b, __m512i v, bool two) {
    store_pair(reinterpret_cast<float*>(a), reinterpret_cast<float*>(b), _mm512_castsi512_ps(v), two);
}

/// tile_write (tile_state.h) with finish_row's operations on 16 lanes: the same bits.
inline void tile_write_avx512(const TileState<float>& st, int x0, int y0, int w, int h, const BlendParams<float>& p,
                              RenderResult& out) {
    const __m512 one = splat16(1.0f), zero = _mm512_setzero_ps();
    const __m512 bg0 = splat16(p.background[0]), bg1 = splat16(p.background[1]), bg2 = splat16(p.background[2]);
    for (int r = 0; r < h; ++r) {
        const int k = r * kTile;
        FinishedRow row;
        const __m512 tr = _mm512_load_ps(st.transmittance + k);
        // blend::finish_pixel: rgb = sum + T background, alpha = 1 - T, depth = sum / alpha or 0.
        _mm512_store_ps(row.red, _mm512_add_ps(_mm512_load_ps(st.red + k), _mm512_mul_ps(tr, bg0)));
        _mm512_store_ps(row.green, _mm512_add_ps(_mm512_load_ps(st.green + k), _mm512_mul_ps(tr, bg1)));
        _mm512_store_ps(row.blue, _mm512_add_ps(_mm512_load_ps(st.blue + k), _mm512_mul_ps(tr, bg2)));
        const __m512 alpha = _mm512_sub_ps(one, tr);
        const __mmask16 positive = _mm512_cmp_ps_mask(alpha, zero, _CMP_GT_OQ);
        _mm512_store_ps(row.alpha, alpha);
        _mm512_store_ps(row.depth, _mm512_maskz_div_ps(positive, _mm512_load_ps(st.depth + k),
                                                       _mm512_mask_mov_ps(one, positive, alpha)));
        copy_row_out(row, st.count + k, x0, y0 + r, w, out);
    }
}

template <bool kContrib>
inline std::uint64_t blend_tile_avx512_impl(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
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
    // Pixel centres x + 0.5, as blend_tile.h's px.
    const __m512 px = _mm512_add_ps(
        _mm512_cvtepi32_ps(_mm512_add_epi32(_mm512_set1_epi32(x0),
                                            _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))),
        splat16(0.5f));
    const __m512 threshold = splat16(p.alpha_threshold), stop = splat16(p.transmittance_stop);
    const __m512 max_alpha = splat16(blend::max_alpha<float>()), one = splat16(1.0f), zero = _mm512_setzero_ps();
    const __m512 minus_half = splat16(-0.5f);

    constexpr std::size_t kPrefetch = 8;
    std::uint64_t evaluated = 0;
    for (std::size_t k = 0; k < n_list && live > 0; ++k) {
        if (k + kPrefetch < n_list) __builtin_prefetch(splats + list[k + kPrefetch]);
        const SplatRecord<float>& s = splats[list[k]];
        const int c0 = std::max(s.x_min - x0, 0), c1 = std::min(s.x_max - x0, kTile - 1);
        const int r0 = std::max(s.y_min - y0, 0), r1 = std::min(s.y_max - y0, kTile - 1);
        const std::uint32_t box = ((2u << c1) - 1u) & ~((1u << c0) - 1u);
        const __m512 dx = _mm512_sub_ps(px, splat16(s.mean_x));
        const __m512 ddx_a = _mm512_mul_ps(_mm512_mul_ps(splat16(s.conic_a), dx), dx);  // (a dx) dx
        const __m512 dx_b = _mm512_mul_ps(splat16(s.conic_b), dx);                       // b dx
        const __m512 opacity = splat16(s.opacity), power_cut = splat16(s.power_cut);
        const __m512 red = splat16(s.rgb[0]), green = splat16(s.rgb[1]), blue = splat16(s.rgb[2]),
                     depth = splat16(s.depth);
        if constexpr (!kContrib) {
            // A box at most 8 columns wide in this tile: two rows per vector, lanes 0-7 the
            // columns [base, base + 8) of row r and lanes 8-15 the same columns of row r + 1.
            // Each pixel gets the row path's operations on the same values (the x terms are
            // permuted, not recomputed), so the image is the same; the stores keep every pixel
            // that is not blended bit for bit (it gains weight 0 times a finite colour, +0, as
            // in the row path, and no sum is -0), which is why a splat with a non-finite colour
            // or depth (power_cut = -infinity) takes the row path. Not for contributions, whose
            // lane sums follow the row path's lanes.
            if (c1 - c0 < 8 && r1 > r0 && s.power_cut > -std::numeric_limits<float>::infinity()) {
                const int base = std::min(c0, 8);
                const __m512i cols = _mm512_add_epi32(_mm512_set1_epi32(base),
                                                      _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3, 4, 5, 6, 7));
                const __m512 ddx_a2 = _mm512_permutexvar_ps(cols, ddx_a), dx_b2 = _mm512_permutexvar_ps(cols, dx_b);
                for (int r = r0; r <= r1; r += 2) {
                    const bool two = r + 1 <= r1;
                    const std::uint32_t m0 = row_live[r] & box, m1 = two ? row_live[r + 1] & box : 0u;
                    if ((m0 | m1) == 0) continue;
                    evaluated += std::uint64_t(__builtin_popcount(m0) + __builtin_popcount(m1));
                    const __mmask16 lanes = __mmask16(((m0 >> base) & 0xffu) | (((m1 >> base) & 0xffu) << 8));
                    const float dy0 = float(y0 + r) + 0.5f - s.mean_y, dy1 = float(y0 + r + 1) + 0.5f - s.mean_y;
                    const __m512 cdy = _mm512_mask_blend_ps(__mmask16(0xff00u), splat16(s.conic_c * dy0 * dy0),
                                                            splat16(s.conic_c * dy1 * dy1));
                    const __m512 dy = _mm512_mask_blend_ps(__mmask16(0xff00u), splat16(dy0), splat16(dy1));
                    const __m512 power = _mm512_sub_ps(_mm512_mul_ps(minus_half, _mm512_add_ps(ddx_a2, cdy)),
                                                       _mm512_mul_ps(dx_b2, dy));
                    if ((_mm512_cmp_ps_mask(power, power_cut, _CMP_GE_OQ) & lanes) == 0) continue;
                    const __m512 e = exp_nonpositive16(power);
                    const __m512 clamped = _mm512_min_ps(_mm512_mul_ps(opacity, e), max_alpha);
                    const __m512 alpha =
                        _mm512_maskz_mov_ps(lanes & _mm512_cmp_ps_mask(power, zero, _CMP_LE_OQ), clamped);
                    // Row r + 1 when there is one, else another row of the tile (the one above
                    // r where r is the last row), whose lanes 8-15 are not in `lanes`: they gain
                    // weight 0 (+0, which changes no sum) and keep their transmittance and count,
                    // so the stores need no branch.
                    const int off0 = r * kTile + base, off1 = off0 + ((two || r + 1 < kTile) ? kTile : -kTile);
                    const __m512 tr = load_pair(st.transmittance + off0, st.transmittance + off1);
                    const __m512 next = _mm512_mul_ps(tr, _mm512_sub_ps(one, alpha));
                    const __mmask16 visible = _mm512_cmp_ps_mask(alpha, threshold, _CMP_GE_OQ);
                    const __mmask16 saturated = visible & _mm512_cmp_ps_mask(next, stop, _CMP_LT_OQ);
                    const __mmask16 blended = visible & _mm512_cmp_ps_mask(next, stop, _CMP_GE_OQ);
                    // Unconditional (a branch on blended != 0 mispredicts): where no lane is
                    // blended every lane gains +0 and keeps its transmittance and count.
                    const __m512 weight = _mm512_maskz_mov_ps(blended, _mm512_mul_ps(alpha, tr));
                    float* const acc[4] = {st.red, st.green, st.blue, st.depth};
                    const __m512 value[4] = {red, green, blue, depth};
                    for (int q = 0; q < 4; ++q)
                        store_pair(acc[q] + off0, acc[q] + off1,
                                   _mm512_add_ps(load_pair(acc[q] + off0, acc[q] + off1),
                                                 _mm512_mul_ps(weight, value[q])),
                                   true);
                    store_pair(st.transmittance + off0, st.transmittance + off1,
                               _mm512_mask_mov_ps(tr, blended, next), true);
                    const __m512i cnt = load_pair(st.count + off0, st.count + off1);
                    store_pair(st.count + off0, st.count + off1,
                               _mm512_mask_add_epi32(cnt, blended, cnt, _mm512_set1_epi32(1)), true);
                    // Lanes 8-15 of saturated are empty when there is no row r + 1.
                    row_live[r] &= ~(std::uint32_t(saturated & 0xffu) << base);
                    row_live[two ? r + 1 : r] &= ~(std::uint32_t(saturated >> 8) << base);
                    live -= __builtin_popcount(unsigned(saturated));
                }
                continue;
            }
            // Wider boxes (and one-row boxes): two tile rows per step, each row the row path's
            // operations below, interleaved so that the two exponentials' dependent chains
            // overlap. A row with no live lane in the box is left alone, as there; a row that
            // does not reach power_cut is still blended when the other row of its pair does:
            // that is the portable kernel's update of the same chunks, which skips no row.
            auto blend_row = [&](int r, std::uint32_t m, __m512 power, __m512 e) __attribute__((always_inline)) {
                const __mmask16 lanes = __mmask16(m);
                const __mmask16 chunks = __mmask16(((m & 0x00ffu) ? 0x00ffu : 0u) | ((m & 0xff00u) ? 0xff00u : 0u));
                const __m512 clamped = _mm512_min_ps(_mm512_mul_ps(opacity, e), max_alpha);
                const __m512 alpha =
                    _mm512_maskz_mov_ps(lanes & _mm512_cmp_ps_mask(power, zero, _CMP_LE_OQ), clamped);
                const int off = r * kTile;
                const __m512 tr = _mm512_load_ps(st.transmittance + off);
                const __m512 next = _mm512_mul_ps(tr, _mm512_sub_ps(one, alpha));
                const __mmask16 visible = _mm512_cmp_ps_mask(alpha, threshold, _CMP_GE_OQ);
                const __mmask16 saturated = visible & _mm512_cmp_ps_mask(next, stop, _CMP_LT_OQ);
                const __mmask16 blended = visible & _mm512_cmp_ps_mask(next, stop, _CMP_GE_OQ);
                const __m512 weight = _mm512_maskz_mov_ps(blended, _mm512_mul_ps(alpha, tr));
                float* const acc[4] = {st.red + off, st.green + off, st.blue + off, st.depth + off};
                const __m512 value[4] = {red, green, blue, depth};
                for (int q = 0; q < 4; ++q)
                    _mm512_mask_store_ps(acc[q], chunks, _mm512_add_ps(_mm512_load_ps(acc[q]), _mm512_mul_ps(weight, value[q])));
                _mm512_mask_store_ps(st.transmittance + off, blended, next);
                __m512i* cnt = reinterpret_cast<__m512i*>(st.count + off);
                _mm512_store_si512(cnt, _mm512_mask_add_epi32(_mm512_load_si512(cnt), blended, _mm512_load_si512(cnt),
                                                              _mm512_set1_epi32(1)));
                row_live[r] &= ~std::uint32_t(saturated);
                live -= __builtin_popcount(unsigned(saturated));
            };
            for (int r = r0; r <= r1; r += 2) {
                const bool two = r + 1 <= r1;
                const std::uint32_t m0 = row_live[r] & box, m1 = two ? row_live[r + 1] & box : 0u;
                if ((m0 | m1) == 0) continue;
                evaluated += std::uint64_t(__builtin_popcount(m0) + __builtin_popcount(m1));
                const float dy0 = float(y0 + r) + 0.5f - s.mean_y, dy1 = float(y0 + r + 1) + 0.5f - s.mean_y;
                const __m512 power0 = _mm512_sub_ps(
                    _mm512_mul_ps(minus_half, _mm512_add_ps(ddx_a, splat16(s.conic_c * dy0 * dy0))), _mm512_mul_ps(dx_b, splat16(dy0)));
                const __m512 power1 = _mm512_sub_ps(
                    _mm512_mul_ps(minus_half, _mm512_add_ps(ddx_a, splat16(s.conic_c * dy1 * dy1))), _mm512_mul_ps(dx_b, splat16(dy1)));
                const bool pass0 = (_mm512_cmp_ps_mask(power0, power_cut, _CMP_GE_OQ) & __mmask16(m0)) != 0;
                const bool pass1 = (_mm512_cmp_ps_mask(power1, power_cut, _CMP_GE_OQ) & __mmask16(m1)) != 0;
                if (!(pass0 | pass1)) continue;
                const __m512 e0 = exp_nonpositive16(power0), e1 = exp_nonpositive16(power1);
                if (m0 != 0) blend_row(r, m0, power0, e0);
                if (m1 != 0) blend_row(r + 1, m1, power1, e1);
            }
            continue;
        }
        __m256 c_max = _mm256_setzero_ps(), c_sum = _mm256_setzero_ps();
        for (int r = r0; r <= r1; ++r) {
            const std::uint32_t m = row_live[r] & box;
            if (m == 0) continue;
            evaluated += std::uint64_t(__builtin_popcount(m));
            const float dy = float(y0 + r) + 0.5f - s.mean_y;
            // blend::gaussian_power: -0.5 ((a dx) dx + (c dy) dy) - (b dx) dy.
            const __m512 power = _mm512_sub_ps(_mm512_mul_ps(minus_half, _mm512_add_ps(ddx_a, splat16(s.conic_c * dy * dy))),
                                               _mm512_mul_ps(dx_b, splat16(dy)));
            const __mmask16 lanes = __mmask16(m);
            if ((_mm512_cmp_ps_mask(power, power_cut, _CMP_GE_OQ) & lanes) == 0) continue;
            // The row update below is blend_row's (the colour-only path above) with the
            // contributions taken in the middle. Sharing one function, returning alpha T and the
            // visible lanes, was measured 1-2 % slower on the colour-only frame (six alternating
            // rounds), so the two are written out; the kernel tests hold both to the
            // portable kernel bit for bit.
            // The chunks the portable kernel would update.
            const __mmask16 chunks = __mmask16(((m & 0x00ffu) ? 0x00ffu : 0u) | ((m & 0xff00u) ? 0xff00u : 0u));
            // blend::splat_alpha, then 0 for lanes outside the box or done.
            const __m512 e = exp_nonpositive16(power);
            const __m512 clamped = _mm512_min_ps(_mm512_mul_ps(opacity, e), max_alpha);
            const __m512 alpha =
                _mm512_maskz_mov_ps(lanes & _mm512_cmp_ps_mask(power, zero, _CMP_LE_OQ), clamped);
            // blend::blend_step.
            const int off = r * kTile;
            const __m512 tr = _mm512_load_ps(st.transmittance + off);
            const __m512 next = _mm512_mul_ps(tr, _mm512_sub_ps(one, alpha));
            const __mmask16 visible = _mm512_cmp_ps_mask(alpha, threshold, _CMP_GE_OQ);
            const __mmask16 saturated = visible & _mm512_cmp_ps_mask(next, stop, _CMP_LT_OQ);
            const __mmask16 blended = visible & _mm512_cmp_ps_mask(next, stop, _CMP_GE_OQ);
            const __m512 alpha_tr = _mm512_mul_ps(alpha, tr);
            const __m512 weight = _mm512_maskz_mov_ps(blended, alpha_tr);
            if constexpr (kContrib) {
                const __m512 cp = _mm512_maskz_mov_ps(visible, alpha_tr);
                c_max = _mm256_max_ps(low8(cp), c_max);
                c_sum = _mm256_add_ps(c_sum, low8(cp));
                c_max = _mm256_max_ps(high8(cp), c_max);
                c_sum = _mm256_add_ps(c_sum, high8(cp));
            }
            _mm512_mask_store_ps(st.red + off, chunks,
                                 _mm512_add_ps(_mm512_load_ps(st.red + off), _mm512_mul_ps(weight, red)));
            _mm512_mask_store_ps(st.green + off, chunks,
                                 _mm512_add_ps(_mm512_load_ps(st.green + off), _mm512_mul_ps(weight, green)));
            _mm512_mask_store_ps(st.blue + off, chunks,
                                 _mm512_add_ps(_mm512_load_ps(st.blue + off), _mm512_mul_ps(weight, blue)));
            _mm512_mask_store_ps(st.depth + off, chunks,
                                 _mm512_add_ps(_mm512_load_ps(st.depth + off), _mm512_mul_ps(weight, depth)));
            _mm512_mask_store_ps(st.transmittance + off, blended, next);
            __m512i* cnt = reinterpret_cast<__m512i*>(st.count + off);
            _mm512_store_si512(cnt, _mm512_mask_add_epi32(_mm512_load_si512(cnt), blended, _mm512_load_si512(cnt),
                                                          _mm512_set1_epi32(1)));
            // No branch on saturated != 0 (it mispredicts); with no lane saturated both are no-ops.
            row_live[r] &= ~std::uint32_t(saturated);
            live -= __builtin_popcount(unsigned(saturated));
        }
        if constexpr (kContrib) {
            LaneContribution<float> here;
            _mm256_store_ps(here.max, c_max);
            _mm256_store_ps(here.sum, c_sum);
            contrib[k] = here.combine();
        }
    }
    tile_write_avx512(st, x0, y0, w, h, p, out);
    return evaluated;
}

}  // namespace

std::uint64_t blend_tile_avx512(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                                const SplatRecord<float>* splats, const BlendParams<float>& p,
                                RenderResult& out, Contribution<float>* contrib) {
    return contrib ? blend_tile_avx512_impl<true>(tx, ty, list, n_list, splats, p, out, contrib)
                   : blend_tile_avx512_impl<false>(tx, ty, list, n_list, splats, p, out, contrib);
}

#pragma GCC diagnostic pop
#pragma GCC pop_options

#else  // no AVX-512 kernel in this build

bool avx512_kernel_available() { return false; }

std::uint64_t blend_tile_avx512(int, int, const std::uint32_t*, std::size_t, const SplatRecord<float>*,
                                const BlendParams<float>&, RenderResult&, Contribution<float>*) {
    return 0;  // never called: avx512_kernel_available() is false
}

#endif

}  // namespace avsplat::detail::cpu
