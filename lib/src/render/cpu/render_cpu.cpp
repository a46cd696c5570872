// CPU splat renderer: projection (parallel over Gaussians), one sort of the visible Gaussians by
// (depth, index) and binning into 16 x 16 tiles in that order, then compositing (parallel over
// tiles). The maths is the shared header-only code (project_and_shade.h for the per-Gaussian work, the
// very function the CUDA renderer's projection kernel calls; tiling.h, blend.h); this file only
// organises the work.
//
// Compositing walks a tile's splats front to back and, for each, the rows of the tile that its
// pixel box covers; a row is processed in two 8-pixel chunks by one branch-free loop (pixels
// outside the box or already saturated take alpha = 0, which blend_step leaves untouched), so
// the compiler vectorises it. Rows and chunks with no pixel left to blend are skipped using a
// bit mask per row. The state of the tile's 256 pixels lives in small arrays.
//
// Per-Gaussian contributions (render.h), when asked, are a second instantiation of the tile loop
// (kContrib = true) that also keeps, for each entry of the tile's list, the max and the sum of
// the splat's c(p) over the tile's pixels; the colour-only instantiation is the loop without
// them. The per-entry values are merged into per-Gaussian arrays after compositing, tile by
// tile in tile order, so the sums do not depend on the number of threads.
#include "render/cpu/render_cpu.h"
#include "common/interrupt_poll.h"
#include "common/radix_sort.h"

#include "render/shared/project_and_shade.h"
#include "render/shared/view_params.h"

#include "render/shared/blend.h"
#include "render/shared/splat_record.h"
#include "render/shared/tiling.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

namespace avsplat::detail {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

constexpr int kTile = tiling::kTileSize;
constexpr int kTilePixels = kTile * kTile;

/// The shared splat record (splat_record.h), cache-line aligned because tiles visit Gaussians in
/// depth order, not in memory order (one line in float, two in double).
template <class T>
struct alignas(64) SplatRecord : blend::SplatRecord<T> {};

using blend::BlendParams;

/// Running state of the 256 pixels of a tile, one array per quantity so that the row loop
/// vectorises. `done` is 1 for a saturated pixel or one outside the image.
template <class T>
struct TileState {
    alignas(64) T transmittance[kTilePixels];
    alignas(64) T red[kTilePixels];
    alignas(64) T green[kTilePixels];
    alignas(64) T blue[kTilePixels];
    alignas(64) T depth[kTilePixels];
    alignas(64) std::int32_t count[kTilePixels];
    alignas(64) std::int32_t done[kTilePixels];
};

/// A visible Gaussian in the sort: its depth_index_key and the tiles it touches, carried along so
/// that binning reads the sorted array in order instead of the records in random order.
struct SortItem {
    std::uint64_t key;
    tiling::TileRect rect;
};

/// Sorts items stably by the upper 32 bits of their keys (the depth), with the common radix sort.
void sort_by_depth(std::vector<SortItem>& items) {
    std::vector<SortItem> tmp(items.size());
    const SortItem* sorted = radix_sort(items.data(), tmp.data(), items.size(), 32, 64,
                                        [](const SortItem& it) { return it.key; });
    if (sorted != items.data()) items.swap(tmp);
}

constexpr int kChunk = 8;  // lanes per vectorised step: one AVX register, two SSE registers

// The compositing functions must be inlined into each ISA clone of blend_tile_float (below) to
// be compiled for that ISA; GCC does not inline a function this large on its own.
#if defined(__GNUC__)
#define AVSPLAT_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define AVSPLAT_ALWAYS_INLINE inline
#endif

/// The max and the sum of one splat's c(p) (render.h) over the pixels of a tile.
template <class T>
struct Contribution {
    T max = T(0);
    T sum = T(0);
};

/// The same per lane of a chunk while a splat is composited: lane-wise updates keep the pixel
/// loop vectorised (a float sum or max across lanes would not, without reassociation); the lanes
/// are combined in lane order at the end, so the result does not depend on the ISA clone.
template <class T>
struct LaneContribution {
    alignas(64) T max[kChunk];
    alignas(64) T sum[kChunk];
};

/// Blends splat `s` into the 8 pixels of tile row `row` starting at lane `base`, those whose
/// lane lies in [c0, c1] and that are not done. Returns the number of pixels it saturated and
/// adds the evaluated pairs to `evaluated`; with kContrib, adds the splat's c(p) at these
/// pixels to `contrib`.
template <bool kContrib, class T>
AVSPLAT_ALWAYS_INLINE int blend_chunk(const SplatRecord<T>& s, TileState<T>& st, int row,
                                      int base, T dy, const T* px, int c0, int c1,
                                      const BlendParams<T>& p, std::uint64_t& evaluated,
                                      LaneContribution<T>& contrib) {
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
    // Branch-free with 32-bit masks so that the compiler vectorises the lanes (this file is
    // compiled with -fno-trapping-math, without which GCC will not if-convert the selects).
    for (int lane = 0; lane < kChunk; ++lane) {
        const std::int32_t live = (base + lane >= c0) & (base + lane <= c1) & (done[lane] == 0);
        const T power = blend::gaussian_power(a, b, c, x[lane] - mx, dy);
        const T alpha = live ? blend::splat_alpha(o, power) : T(0);
        const blend::BlendStep<T> step =
            blend::blend_step(alpha, tr[lane], p.alpha_threshold, p.transmittance_stop);
        if constexpr (kContrib) {
            // Blended or stopping the pixel: alpha T (render.h); lanes not live have alpha 0.
            const T c = alpha >= p.alpha_threshold ? alpha * tr[lane] : T(0);
            contrib.max[lane] = c > contrib.max[lane] ? c : contrib.max[lane];
            contrib.sum[lane] += c;
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

/// Composites tile (tx, ty) from its list of Gaussian indices in compositing order and writes
/// its pixels to the result. With kContrib, writes entry k's contribution over the tile to
/// contrib[k] (n_list entries, zero-initialised by the caller).
/// Returns the number of evaluated Gaussian-pixel pairs.
template <bool kContrib, class T>
AVSPLAT_ALWAYS_INLINE std::uint64_t blend_tile(int tx, int ty, const std::uint32_t* list,
                                               std::size_t n_list, const SplatRecord<T>* splats,
                                               const BlendParams<T>& p, RenderResult& out,
                                               Contribution<T>* contrib) {
    (void)contrib;  // read only by the kContrib instantiation
    TileState<T> st;
    const int x0 = tx * kTile, y0 = ty * kTile;
    const int w = std::min(kTile, out.width - x0), h = std::min(kTile, out.height - y0);
    for (int r = 0; r < kTile; ++r) {
        for (int l = 0; l < kTile; ++l) {
            const int k = r * kTile + l;
            st.transmittance[k] = T(1);
            st.red[k] = st.green[k] = st.blue[k] = st.depth[k] = T(0);
            st.count[k] = 0;
            st.done[k] = (r < h && l < w) ? 0 : 1;
        }
    }
    // Per row, the lanes still to be blended: rows and 8-lane chunks without any are skipped.
    std::uint32_t row_live[kTile];
    for (int r = 0; r < kTile; ++r) row_live[r] = live_bits(st, r);
    int live = w * h;
    T px[kTile];
    for (int l = 0; l < kTile; ++l) px[l] = T(x0 + l) + T(0.5);

    // The list is in depth order, so the records are read in no particular memory order:
    // fetch a few ahead to hide the latency.
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
        if constexpr (kContrib) {
            Contribution<T> total;
            for (int l = 0; l < kChunk; ++l) {
                total.max = here.max[l] > total.max ? here.max[l] : total.max;
                total.sum += here.sum[l];
            }
            contrib[k] = total;
        }
    }

    for (int r = 0; r < h; ++r) {
        for (int l = 0; l < w; ++l) {
            const int k = r * kTile + l;
            const std::size_t pix = std::size_t(y0 + r) * std::size_t(out.width) + std::size_t(x0 + l);
            const T sum[3] = {st.red[k], st.green[k], st.blue[k]};
            T rgb[3], alpha, depth;
            blend::finish_pixel(st.transmittance[k], sum, st.depth[k], p.background, rgb, alpha, depth);
            for (int c = 0; c < 3; ++c) out.color[3 * pix + c] = float(rgb[c]);
            out.alpha[pix] = float(alpha);
            out.depth[pix] = float(depth);
            out.contributors[pix] = st.count[k];
        }
    }
    return evaluated;
}

// The float tile loop is built for AVX2 as well as the baseline ISA and picked at load time
// where the toolchain supports it (GNU ifunc). The instructions differ, the arithmetic does not:
// ISO C++ mode keeps -ffp-contract=off, so no FMA is formed and both give the same image.
#if defined(__GNUC__) && defined(__x86_64__) && defined(__linux__) && !defined(__clang__)
#define AVSPLAT_CPU_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define AVSPLAT_CPU_CLONES
#endif

AVSPLAT_CPU_CLONES
std::uint64_t blend_tile_float(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                               const SplatRecord<float>* splats, const BlendParams<float>& p,
                               RenderResult& out) {
    return blend_tile<false>(tx, ty, list, n_list, splats, p, out, static_cast<Contribution<float>*>(nullptr));
}

AVSPLAT_CPU_CLONES
std::uint64_t blend_tile_float_contrib(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                                       const SplatRecord<float>* splats, const BlendParams<float>& p,
                                       RenderResult& out, Contribution<float>* contrib) {
    return blend_tile<true>(tx, ty, list, n_list, splats, p, out, contrib);
}

/// contrib == nullptr: colour only; else the contributions of the tile's entries (blend_tile).
std::uint64_t blend_tile_dispatch(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                                  const SplatRecord<float>* splats, const BlendParams<float>& p,
                                  RenderResult& out, Contribution<float>* contrib) {
    return contrib ? blend_tile_float_contrib(tx, ty, list, n_list, splats, p, out, contrib)
                   : blend_tile_float(tx, ty, list, n_list, splats, p, out);
}

std::uint64_t blend_tile_dispatch(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                                  const SplatRecord<double>* splats, const BlendParams<double>& p,
                                  RenderResult& out, Contribution<double>* contrib) {
    return contrib ? blend_tile<true>(tx, ty, list, n_list, splats, p, out, contrib)
                   : blend_tile<false>(tx, ty, list, n_list, splats, p, out, contrib);
}

}  // namespace

template <class T>
RenderResult render_cpu(const GaussianCloud& cloud, const Camera& camera,
                        const RenderOptions& options) {
    RenderResult out;
    out.width = camera.width;
    out.height = camera.height;
    const std::size_t n_pixels = std::size_t(camera.width) * std::size_t(camera.height);
    out.color.assign(3 * n_pixels, 0.0f);
    out.alpha.assign(n_pixels, 0.0f);
    out.depth.assign(n_pixels, 0.0f);
    out.contributors.assign(n_pixels, 0);
    RenderStats& stats = out.stats;
    stats.gaussians = cloud.size();
    stats.threads = omp_get_max_threads();

    // ---- projection, culling and colour, one Gaussian at a time -------------------------
    auto t0 = Clock::now();
    const preprocess::ViewParams<T> view =
        preprocess::view_params<T>(camera, options, cloud.sh_degree);
    const std::int64_t n = std::int64_t(cloud.size());
    const int coeffs = cloud.sh_coeffs();
    // Default-initialised (not zeroed): only visible Gaussians' records are written and read.
    const std::unique_ptr<SplatRecord<T>[]> splats(new SplatRecord<T>[cloud.size()]);
    std::vector<std::uint32_t> n_tiles(cloud.size());

    InterruptPoll poll;
#pragma omp parallel for schedule(static)
    for (std::int64_t i = 0; i < n; ++i) {
        if (poll.stop(i)) {
            n_tiles[i] = 0;
            continue;
        }
        n_tiles[i] = preprocess::project_record(view, &cloud.means[3 * i], &cloud.scales[3 * i],
                                                &cloud.rotations[4 * i], cloud.opacities[i],
                                                &cloud.sh[std::size_t(i) * coeffs * 3], splats[i]);
    }
    poll.throw_if_stopped();
    stats.seconds_projection = seconds_since(t0);

    // ---- sorting and binning ----------------------------------------------------------------
    // The visible Gaussians are sorted once by (depth, index); walking them in that order and
    // appending each to the tiles it touches leaves every tile's list sorted, with no per-tile
    // sort. The walk is split among threads by ranges of the sorted order and each thread
    // writes at offsets fixed by the counts of the threads before it, so the lists do not
    // depend on the number of threads.
    t0 = Clock::now();
    std::vector<SortItem> order;
    order.reserve(cloud.size());
    for (std::int64_t i = 0; i < n; ++i) {
        if (n_tiles[i] == 0) continue;
        const SplatRecord<T>& s = splats[i];
        order.push_back({tiling::depth_index_key(float(s.depth), std::uint32_t(i)),
                         tiling::tile_rect(s.x_min, s.x_max, s.y_min, s.y_max)});
    }
    sort_by_depth(order);
    const int tiles_x = tiling::tiles_along(camera.width), tiles_y = tiling::tiles_along(camera.height);
    const std::size_t n_tile_ids = std::size_t(tiles_x) * std::size_t(tiles_y);
    std::vector<std::size_t> offsets(n_tile_ids + 1, 0);
    std::vector<std::uint32_t> lists;
    const int max_threads = omp_get_max_threads();
    std::vector<std::size_t> cursor(std::size_t(max_threads) * n_tile_ids, 0);
#pragma omp parallel num_threads(max_threads)
    {
        const std::size_t team = std::size_t(omp_get_num_threads()), me = std::size_t(omp_get_thread_num());
        const std::size_t begin = order.size() * me / team, end = order.size() * (me + 1) / team;
        std::size_t* mine = cursor.data() + me * n_tile_ids;
        auto for_each_tile = [tiles_x](const tiling::TileRect& rect, auto&& f) {
            for (int ty = rect.y0; ty < rect.y1; ++ty)
                for (int tx = rect.x0; tx < rect.x1; ++tx) f(std::size_t(ty) * std::size_t(tiles_x) + std::size_t(tx));
        };
        for (std::size_t k = begin; k < end; ++k)
            for_each_tile(order[k].rect, [&](std::size_t tile) { ++mine[tile]; });
#pragma omp barrier
#pragma omp single
        {
            // Turn the counts into write positions: tile by tile, thread by thread.
            std::size_t pos = 0;
            for (std::size_t tile = 0; tile < n_tile_ids; ++tile) {
                offsets[tile] = pos;
                for (std::size_t t = 0; t < team; ++t) {
                    const std::size_t c = cursor[t * n_tile_ids + tile];
                    cursor[t * n_tile_ids + tile] = pos;
                    pos += c;
                }
            }
            offsets[n_tile_ids] = pos;
            lists.resize(pos);
        }
        for (std::size_t k = begin; k < end; ++k) {
            const std::uint32_t i = tiling::key_index(order[k].key);
            for_each_tile(order[k].rect, [&](std::size_t tile) { lists[mine[tile]++] = i; });
        }
    }
    stats.visible = order.size();
    stats.tile_instances = lists.size();
    stats.seconds_sorting = seconds_since(t0);

    // ---- compositing, one tile at a time --------------------------------------------------
    t0 = Clock::now();
    const BlendParams<T> bp{T(options.alpha_threshold), T(options.transmittance_stop),
                            {T(options.background[0]), T(options.background[1]), T(options.background[2])}};
    std::uint64_t blends = 0;
    // One entry per tile instance, parallel to `lists`, only when contributions are asked for.
    std::vector<Contribution<T>> instance_contrib(options.gaussian_contributions ? lists.size() : 0);
    Contribution<T>* const contrib = options.gaussian_contributions ? instance_contrib.data() : nullptr;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : blends)
    for (std::int64_t k = 0; k < std::int64_t(n_tile_ids); ++k) {
        if (poll.stop()) continue;
        const int tx = int(k % tiles_x), ty = int(k / tiles_x);
        blends += blend_tile_dispatch(tx, ty, lists.data() + offsets[k], offsets[k + 1] - offsets[k],
                                      splats.get(), bp, out, contrib ? contrib + offsets[k] : nullptr);
    }
    poll.throw_if_stopped();
    stats.blends = blends;
    if (options.gaussian_contributions) {
        // Tile by tile in tile order (the order of `lists`), whatever thread blended the tile.
        out.has_gaussian_contributions = true;
        out.contribution_max.assign(cloud.size(), 0.0f);
        std::vector<double> sum(cloud.size(), 0.0);
        for (std::size_t j = 0; j < lists.size(); ++j) {
            const std::uint32_t g = lists[j];
            const float m = float(instance_contrib[j].max);
            if (m > out.contribution_max[g]) out.contribution_max[g] = m;
            sum[g] += double(instance_contrib[j].sum);
        }
        out.contribution_sum.assign(sum.begin(), sum.end());
    }
    std::uint64_t contributions = 0;
    for (const std::int32_t c : out.contributors) contributions += std::uint64_t(c);
    stats.contributions = contributions;
    stats.seconds_blending = seconds_since(t0);
    return out;
}

template RenderResult render_cpu<float>(const GaussianCloud&, const Camera&, const RenderOptions&);
template RenderResult render_cpu<double>(const GaussianCloud&, const Camera&, const RenderOptions&);

}  // namespace avsplat::detail
