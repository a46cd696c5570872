// The portable tile kernel of the CPU renderer: plain C++ over the 8 lanes of a chunk, the
// reference the AVX2 kernel (blend_tile_avx2.cpp) is held to and the kernel of the float64
// path and of CPUs without AVX2 (cpu_kernel.h). The arithmetic is blend.h's, operation for
// operation; the compiler may vectorise the lane loop for the baseline ISA (SSE2), which
// changes no result (the library is built without FMA contraction).
//
// Compositing walks a tile's splats front to back and, for each, the rows of the tile that its
// pixel box covers; a row is processed in two 8-pixel chunks by one branch-free loop (pixels
// outside the box or already saturated take alpha = 0, which blend_step leaves untouched).
// Rows and chunks with no pixel left to blend are skipped using a bit mask per row. The state
// of the tile's 256 pixels lives in small arrays (tile_state.h).
//
// Per-Gaussian contributions (render.h), when asked, are a second instantiation of the tile
// loop (kContrib = true) that also keeps, for each entry of the tile's list, the max and the
// sum of the splat's c(p) over the tile's pixels.
#pragma once

#include "render/cpu/tile_state.h"

namespace avsplat::detail::cpu {

// The compositing functions must be inlined into their callers to vectorise well; GCC does
// not inline a function this large on its own.
#if defined(__GNUC__)
#define AVSPLAT_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define AVSPLAT_ALWAYS_INLINE inline
#endif

/// Blends splat `s` into the 8 pixels of tile row `row` starting at lane `base`, those whose
/// lane lies in [c0, c1] and that are not done. Returns the number of pixels it saturated and
/// adds the evaluated pairs to `evaluated`; with kContrib, adds the splat's c(p) at these
/// pixels to `contrib`.
template <bool kContrib, class T>
AVSPLAT_ALWAYS_INLINE int blend_chunk(const SplatRecord<T>& s, TileState<T>& st, int row, int base, T dy,
                                      const T* px, int c0, int c1, const BlendParams<T>& p,
                                      std::uint64_t& evaluated, LaneContribution<T>& contrib) {
    const int off = row * kTile + base;
    T* __restrict tr = st.transmittance + off;
    T* __restrict red = st.red + off;
    T* __restrict green = st.green + off;
    T* __restrict blue = st.blue + off;
    T* __restrict dep = st.depth + off;
    std::int32_t* __restrict cnt = st.count + off;
    std::int32_t* __restrict done = st.done + off;
    const T* __restrict x = px + base;
    const T mx = s.mean_x, a = s.conic_a, b = s.conic_b, c = s.conic_c, o = s.opacity;
    const T r = s.rgb[0], g = s.rgb[1], bl = s.rgb[2], z = s.depth;
    std::int32_t saturated = 0, live_count = 0;
    // Branch-free with 32-bit masks so that the compiler vectorises the lanes (the renderer is
    // compiled with -fno-trapping-math, without which GCC will not if-convert the selects).
    for (int lane = 0; lane < kChunk; ++lane) {
        const std::int32_t live = (base + lane >= c0) & (base + lane <= c1) & (done[lane] == 0);
        const T power = blend::gaussian_power(a, b, c, x[lane] - mx, dy);
        const T alpha = live ? blend::splat_alpha(o, power) : T(0);
        const blend::BlendStep<T> step = blend::blend_step(alpha, tr[lane], p.alpha_threshold, p.transmittance_stop);
        if constexpr (kContrib) {
            // Blended or stopping the pixel: alpha T (render.h); lanes not live have alpha 0.
            const T cp = alpha >= p.alpha_threshold ? alpha * tr[lane] : T(0);
            contrib.max[lane] = cp > contrib.max[lane] ? cp : contrib.max[lane];
            contrib.sum[lane] += cp;
        }
        red[lane] += step.weight * r;
        green[lane] += step.weight * g;
        blue[lane] += step.weight * bl;
        dep[lane] += step.weight * z;
        tr[lane] = step.next_transmittance;
        cnt[lane] += step.blended;
        done[lane] |= step.saturated;
        saturated += step.saturated;
        live_count += live;
    }
    evaluated += std::uint64_t(live_count);
    return saturated;
}

/// Bit l set for each lane l of tile row `row` that is not done.
template <class T>
AVSPLAT_ALWAYS_INLINE std::uint32_t live_bits(const TileState<T>& st, int row) {
    std::uint32_t m = 0;
    for (int l = 0; l < kTile; ++l) m |= std::uint32_t(st.done[row * kTile + l] == 0) << l;
    return m;
}

/// Composites tile (tx, ty) from its `n_list` splats `splats[list[k]]`, in compositing order,
/// and writes its pixels to `out`. With kContrib, writes entry k's contribution over the tile
/// to contrib[k]. Returns the number of evaluated Gaussian-pixel pairs (RenderStats::blends).
template <bool kContrib, class T>
AVSPLAT_ALWAYS_INLINE std::uint64_t blend_tile(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                                               const SplatRecord<T>* splats, const BlendParams<T>& p,
                                               RenderResult& out, Contribution<T>* contrib) {
    (void)contrib;  // read only by the kContrib instantiation
    TileState<T> st;
    const int x0 = tx * kTile, y0 = ty * kTile;
    const int w = std::min(kTile, out.width - x0), h = std::min(kTile, out.height - y0);
    tile_start(st, w, h);
    // Per row, the lanes still to be blended: rows and 8-lane chunks without any are skipped.
    std::uint32_t row_live[kTile];
    for (int r = 0; r < kTile; ++r) row_live[r] = live_bits(st, r);
    int live = w * h;
    T px[kTile];
    for (int l = 0; l < kTile; ++l) px[l] = T(x0 + l) + T(0.5);

    constexpr std::size_t kPrefetch = 8;
    std::uint64_t evaluated = 0;
    for (std::size_t k = 0; k < n_list && live > 0; ++k) {
        if (k + kPrefetch < n_list) __builtin_prefetch(splats + list[k + kPrefetch]);
        const SplatRecord<T>& s = splats[list[k]];
        const int c0 = std::max(s.x_min - x0, 0), c1 = std::min(s.x_max - x0, kTile - 1);
        const int r0 = std::max(s.y_min - y0, 0), r1 = std::min(s.y_max - y0, kTile - 1);
        const std::uint32_t box = ((2u << c1) - 1u) & ~((1u << c0) - 1u);
        LaneContribution<T> here;
        if constexpr (kContrib) {
            for (int l = 0; l < kChunk; ++l) here.max[l] = here.sum[l] = T(0);
        }
        for (int r = r0; r <= r1; ++r) {
            const std::uint32_t m = row_live[r] & box;
            if (m == 0) continue;
            const T dy = T(y0 + r) + T(0.5) - s.mean_y;
            int sat = 0;
            if (m & 0x00ffu) sat += blend_chunk<kContrib>(s, st, r, 0, dy, px, c0, c1, p, evaluated, here);
            if (m & 0xff00u) sat += blend_chunk<kContrib>(s, st, r, kChunk, dy, px, c0, c1, p, evaluated, here);
            if (sat != 0) {
                row_live[r] = live_bits(st, r);
                live -= sat;
            }
        }
        if constexpr (kContrib) contrib[k] = here.combine();
    }
    tile_write(st, x0, y0, w, h, p, out);
    return evaluated;
}

}  // namespace avsplat::detail::cpu
