// CPU splat renderer: projection (parallel over Gaussians), one sort of the visible Gaussians by
// (depth, index) and binning into 16 x 16 tiles in that order, then compositing (parallel over
// tiles). The maths is the shared header-only code (project_and_shade.h for the per-Gaussian work, the
// very function the CUDA renderer's projection kernel calls; tiling.h, blend.h); this file only
// organises the work. The tile kernels are blend_tile.h (portable), blend_tile_avx2.cpp and
// blend_tile_avx512.cpp, picked per frame by cpu_kernel.h; all give the same image.
//
// Per-Gaussian contributions (render.h), when asked, are computed by the tile kernels for each
// entry of a tile's list and merged into per-Gaussian arrays after compositing, tile by tile in
// tile order, so the sums do not depend on the number of threads.
#include "render/cpu/render_cpu.h"
#include "core/interrupt_poll.h"
#include "common/radix_sort.h"

#include "render/shared/project_and_shade.h"
#include "render/shared/view_params.h"

#include "render/cpu/blend_tile.h"
#include "render/cpu/blend_tile_avx2.h"
#include "render/cpu/blend_tile_avx512.h"
#include "render/cpu/cpu_kernel.h"
#include "render/cpu/project_splats.h"
#include "render/cpu/render_workspace.h"
#include "render/cpu/tile_state.h"
#include "render/shared/tiling.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

namespace avsplat::detail {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

using cpu::BlendParams;
using cpu::Contribution;
using cpu::SplatRecord;

/// contrib == nullptr: colour only; else the contributions of the tile's entries (blend_tile).
std::uint64_t blend_tile_dispatch(cpu::CpuKernel kernel, int tx, int ty, const std::uint32_t* list,
                                  std::size_t n_list, const SplatRecord<float>* splats,
                                  const BlendParams<float>& p, RenderResult& out, Contribution<float>* contrib) {
    if (kernel == cpu::CpuKernel::Avx512) return cpu::blend_tile_avx512(tx, ty, list, n_list, splats, p, out, contrib);
    if (kernel == cpu::CpuKernel::Avx2) return cpu::blend_tile_avx2(tx, ty, list, n_list, splats, p, out, contrib);
    return contrib ? cpu::blend_tile<true>(tx, ty, list, n_list, splats, p, out, contrib)
                   : cpu::blend_tile<false>(tx, ty, list, n_list, splats, p, out, contrib);
}

std::uint64_t blend_tile_dispatch(cpu::CpuKernel, int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                                  const SplatRecord<double>* splats, const BlendParams<double>& p,
                                  RenderResult& out, Contribution<double>* contrib) {
    return contrib ? cpu::blend_tile<true>(tx, ty, list, n_list, splats, p, out, contrib)
                   : cpu::blend_tile<false>(tx, ty, list, n_list, splats, p, out, contrib);
}

}  // namespace

template <class T>
RenderResult render_cpu(const GaussianCloud& cloud, const Camera& camera,
                        const RenderOptions& options, RenderWorkspace::Buffers& buffers) {
    const cpu::CpuKernel kernel = cpu::cpu_kernel();
    RenderResult out;
    out.width = camera.width;
    out.height = camera.height;
    const std::size_t n_pixels = std::size_t(camera.width) * std::size_t(camera.height);
    // Every pixel is written by its tile (tile_write), so the images need no clearing; their
    // memory is a recycled result's where the caller gave one back (RenderWorkspace::recycle).
    buffers.take_images(out);
    out.color.resize(3 * n_pixels);
    out.alpha.resize(n_pixels);
    out.depth.resize(n_pixels);
    out.contributors.resize(n_pixels);
    RenderStats& stats = out.stats;
    stats.gaussians = cloud.size();
    stats.threads = omp_get_max_threads();

    // ---- projection, culling and colour (project_splats.h) --------------------------------
    auto t0 = Clock::now();
    const preprocess::ViewParams<T> view =
        preprocess::view_params<T>(camera, options, cloud.sh_degree);
    const std::int64_t n = std::int64_t(cloud.size());
    // Default-initialised (not zeroed): only visible Gaussians' records are written and read.
    SplatRecord<T>* const splats = buffers.records.get<SplatRecord<T>>(cloud.size(), buffers.reuse);
    // The sort key of each Gaussian (tiling::depth_index_key), kCulled for a culled one: written
    // here while the record is hot, so that the sort's input is gathered from 8 bytes per
    // Gaussian rather than from the records.
    constexpr std::uint64_t kCulled = cpu::kCulledKey;
    std::uint64_t* const keys = buffers.keys.get<std::uint64_t>(cloud.size(), buffers.reuse);

    // Ranges of 256 Gaussians: a multiple of the vector kernels' blocks of 8, and the interrupt
    // check runs at each range's start, every 256 Gaussians as when this loop went one by one.
    // Float64 frames (the reference path) project one Gaussian at a time, float32 frames with
    // the kernel of the frame (the same records on every kernel).
    constexpr std::int64_t kRange = 256;
    InterruptPoll poll;
#pragma omp parallel for schedule(static)
    for (std::int64_t begin = 0; begin < n; begin += kRange) {
        const std::int64_t end = std::min(n, begin + kRange);
        if (poll.stop(begin)) {
            std::fill(keys + begin, keys + end, kCulled);
            continue;
        }
        if constexpr (std::is_same_v<T, float>) {
            cpu::project_splats(kernel, view, cloud, T(options.alpha_threshold), begin, end, splats, keys);
        } else {
            for (std::int64_t i = begin; i < end; ++i)
                cpu::project_one(view, cloud, T(options.alpha_threshold), i, splats[i], keys[i]);
        }
    }
    poll.throw_if_stopped();
    stats.seconds_projection = seconds_since(t0);

    // ---- sorting and binning ----------------------------------------------------------------
    // The visible Gaussians are sorted once by (depth, index) and their records copied in that
    // order, so that every tile's list, a subsequence of it, walks the records forwards through
    // memory. Walking them in that order and appending each to the tiles it touches leaves
    // every tile's list sorted, with no per-tile sort. Every pass is split among threads by
    // static ranges, and each thread writes at offsets fixed by the counts of the threads before
    // it, so nothing depends on the number of threads. All buffers come from the workspace.
    t0 = Clock::now();
    const int max_threads = omp_get_max_threads();
    const int tiles_x = tiling::tiles_along(camera.width), tiles_y = tiling::tiles_along(camera.height);
    const std::size_t n_tile_ids = std::size_t(tiles_x) * std::size_t(tiles_y);
    // Per thread: its count of visible keys and their smallest and largest depth bits
    // (compaction), then its count and cursor per tile (binning).
    std::size_t* const cursor = buffers.counts.get<std::size_t>(
        std::size_t(max_threads) * std::max<std::size_t>(n_tile_ids, 3), buffers.reuse);
    std::size_t* const offsets = buffers.offsets.get<std::size_t>(n_tile_ids + 1, buffers.reuse);
    std::uint64_t* order = buffers.order.get<std::uint64_t>(std::size_t(n), buffers.reuse);
    std::uint64_t* const order_tmp = buffers.order_tmp.get<std::uint64_t>(std::size_t(n), buffers.reuse);
    std::size_t n_visible = 0;
    int depth_bits = 0;  // bits of (depth key - smallest depth key) over the visible Gaussians
    // Compaction of the visible keys, in index order, each rewritten as
    // ((depth_bits(depth) - smallest) << 32) | index: the same order on fewer bits, so the sort
    // needs only as many digits as the depth range of this frame does.
#pragma omp parallel num_threads(max_threads)
    {
        const int team = omp_get_num_threads(), me = omp_get_thread_num();
        const std::size_t b = chunk_begin(std::size_t(n), me, team), e = chunk_begin(std::size_t(n), me + 1, team);
        std::size_t visible = 0;
        std::uint32_t lo = ~std::uint32_t(0), hi = 0;
        for (std::size_t i = b; i < e; ++i) {
            const std::uint64_t key = keys[i];
            if (key == kCulled) continue;
            const std::uint32_t d = std::uint32_t(key >> 32);
            lo = std::min(lo, d);
            hi = std::max(hi, d);
            ++visible;
        }
        std::size_t* const mine = cursor + 3 * std::size_t(me);
        mine[0] = visible;
        mine[1] = lo;
        mine[2] = hi;
#pragma omp barrier
        std::size_t start = 0;
        std::uint32_t lo_all = ~std::uint32_t(0), hi_all = 0;
        for (int t = 0; t < team; ++t) {
            const std::size_t* other = cursor + 3 * std::size_t(t);
            if (t < me) start += other[0];
            if (other[0] != 0) {
                lo_all = std::min(lo_all, std::uint32_t(other[1]));
                hi_all = std::max(hi_all, std::uint32_t(other[2]));
            }
        }
        std::uint64_t* out_keys = order + start;
        for (std::size_t i = b; i < e; ++i) {
            const std::uint64_t key = keys[i];
            if (key == kCulled) continue;
            *out_keys++ = (std::uint64_t(std::uint32_t(key >> 32) - lo_all) << 32) | (key & 0xffffffffu);
        }
        if (me == team - 1) {
            n_visible = start + visible;
            const std::uint32_t range = n_visible ? hi_all - lo_all : 0;
            while (depth_bits < 32 && (std::uint64_t(range) >> depth_bits) != 0) ++depth_bits;
        }
    }
    // The sort and the binning below poll too: with millions of visible Gaussians, or large ones
    // covering many tiles, they run for seconds.
    order = radix_sort(order, order_tmp, n_visible, 32, 32 + depth_bits, [](std::uint64_t k) { return k; }, &poll);
    poll.throw_if_stopped();
    SplatRecord<T>* const sorted = buffers.sorted.get<SplatRecord<T>>(n_visible, buffers.reuse);
    // The tile rectangle of each sorted record, 16 bytes instead of its 64 or 128 for the two
    // passes over tiles below.
    tiling::TileRect* const rects = buffers.rects.get<tiling::TileRect>(n_visible, buffers.reuse);
    // Two parallel regions over the same static split of the sorted order, one part per thread
    // of the first: the copy and the count, then, after the prefix and the allocation of the
    // lists outside any region (so that running out of memory throws std::bad_alloc rather than
    // ending the process), the scatter.
    auto for_each_tile = [tiles_x](const tiling::TileRect& rect, auto&& f) {
        for (int ty = rect.y0; ty < rect.y1; ++ty)
            for (int tx = rect.x0; tx < rect.x1; ++tx) f(std::size_t(ty) * std::size_t(tiles_x) + std::size_t(tx));
    };
    int team = 1;
#pragma omp parallel num_threads(max_threads)
    {
        const int threads = omp_get_num_threads(), me = omp_get_thread_num();
        if (me == 0) team = threads;
        const std::size_t begin = chunk_begin(n_visible, me, threads), end = chunk_begin(n_visible, me + 1, threads);
        std::size_t* mine = cursor + std::size_t(me) * n_tile_ids;
        std::fill(mine, mine + n_tile_ids, std::size_t(0));
        // The copy into depth order (a gather: a loop of nothing else keeps the most loads in
        // flight) with each record's tile rectangle, then the count of each tile's entries over
        // the thread's part of the copy.
        constexpr std::size_t kPrefetch = 48;
        for (std::size_t k = begin; k < end; ++k) {
            if (poll.stop(std::int64_t(k - begin))) break;
            if (k + kPrefetch < end) __builtin_prefetch(splats + tiling::key_index(order[k + kPrefetch]));
            const SplatRecord<T>& s = splats[tiling::key_index(order[k])];
            sorted[k] = s;
            rects[k] = tiling::tile_rect(s.x_min, s.x_max, s.y_min, s.y_max);
        }
        for (std::size_t k = begin; k < end; ++k) {
            if (poll.stop(std::int64_t(k - begin))) break;
            for_each_tile(rects[k], [&](std::size_t tile) { ++mine[tile]; });
        }
    }
    poll.throw_if_stopped();
    // Turn the counts into write positions: tile by tile, thread by thread.
    std::size_t pos = 0;
    for (std::size_t tile = 0; tile < n_tile_ids; ++tile) {
        offsets[tile] = pos;
        for (int t = 0; t < team; ++t) {
            const std::size_t c = cursor[std::size_t(t) * n_tile_ids + tile];
            cursor[std::size_t(t) * n_tile_ids + tile] = pos;
            pos += c;
        }
    }
    offsets[n_tile_ids] = pos;
    std::uint32_t* const lists = buffers.lists.get<std::uint32_t>(pos, buffers.reuse);  // positions in `sorted`
#pragma omp parallel num_threads(team)
    {
        const int threads = omp_get_num_threads(), me = omp_get_thread_num();
        // Part by part as counted; a smaller team than the first (the runtime may give one)
        // takes the parts in turn.
        for (int part = me; part < team; part += threads) {
            const std::size_t begin = chunk_begin(n_visible, part, team), end = chunk_begin(n_visible, part + 1, team);
            std::size_t* mine = cursor + std::size_t(part) * n_tile_ids;
            for (std::size_t k = begin; k < end; ++k) {
                if (poll.stop(std::int64_t(k - begin))) break;
                for_each_tile(rects[k], [&](std::size_t tile) { lists[mine[tile]++] = std::uint32_t(k); });
            }
        }
    }
    poll.throw_if_stopped();
    const std::size_t n_instances = offsets[n_tile_ids];
    stats.visible = n_visible;
    stats.tile_instances = n_instances;
    stats.seconds_sorting = seconds_since(t0);

    // ---- compositing, one tile at a time --------------------------------------------------
    t0 = Clock::now();
    const BlendParams<T> bp{T(options.alpha_threshold), T(options.transmittance_stop),
                            {T(options.background[0]), T(options.background[1]), T(options.background[2])}};
    std::uint64_t blends = 0;
    // One entry per tile instance, parallel to `lists`, only when contributions are asked for.
    std::vector<Contribution<T>> instance_contrib(options.gaussian_contributions ? n_instances : 0);
    Contribution<T>* const contrib = options.gaussian_contributions ? instance_contrib.data() : nullptr;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : blends)
    for (std::int64_t k = 0; k < std::int64_t(n_tile_ids); ++k) {
        if (poll.stop()) continue;
        const int tx = int(k % tiles_x), ty = int(k / tiles_x);
        blends += blend_tile_dispatch(kernel, tx, ty, lists + offsets[k], offsets[k + 1] - offsets[k],
                                      sorted, bp, out, contrib ? contrib + offsets[k] : nullptr);
    }
    poll.throw_if_stopped();
    stats.blends = blends;
    if (options.gaussian_contributions) {
        // Tile by tile in tile order (the order of `lists`), whatever thread blended the tile.
        out.has_gaussian_contributions = true;
        out.contribution_max.assign(cloud.size(), 0.0f);
        std::vector<double> sum(cloud.size(), 0.0);
        for (std::size_t j = 0; j < n_instances; ++j) {
            const std::uint32_t g = tiling::key_index(order[lists[j]]);
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

template RenderResult render_cpu<float>(const GaussianCloud&, const Camera&, const RenderOptions&,
                                        RenderWorkspace::Buffers&);
template RenderResult render_cpu<double>(const GaussianCloud&, const Camera&, const RenderOptions&,
                                         RenderWorkspace::Buffers&);

}  // namespace avsplat::detail
