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
#include "common/interrupt_poll.h"
#include "common/radix_sort.h"

#include "render/shared/project_and_shade.h"
#include "render/shared/view_params.h"

#include "render/cpu/blend_tile.h"
#include "render/cpu/blend_tile_avx2.h"
#include "render/cpu/blend_tile_avx512.h"
#include "render/cpu/cpu_kernel.h"
#include "render/cpu/project_splats.h"
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

/// Sorts depth_index_keys stably by their upper 32 bits (the depth), with the common radix sort.
void sort_by_depth(std::vector<std::uint64_t>& keys) {
    std::vector<std::uint64_t> tmp(keys.size());
    const std::uint64_t* sorted =
        radix_sort(keys.data(), tmp.data(), keys.size(), 32, 64);
    if (sorted != keys.data()) keys.swap(tmp);
}

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
                        const RenderOptions& options) {
    const cpu::CpuKernel kernel = cpu::cpu_kernel();
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

    // ---- projection, culling and colour (project_splats.h) --------------------------------
    auto t0 = Clock::now();
    const preprocess::ViewParams<T> view =
        preprocess::view_params<T>(camera, options, cloud.sh_degree);
    const std::int64_t n = std::int64_t(cloud.size());
    // Default-initialised (not zeroed): only visible Gaussians' records are written and read.
    std::unique_ptr<SplatRecord<T>[]> splats(new SplatRecord<T>[cloud.size()]);
    // The sort key of each Gaussian (tiling::depth_index_key), kCulled for a culled one: written
    // here while the record is hot, so that the sort's input is gathered from 8 bytes per
    // Gaussian rather than from the records.
    constexpr std::uint64_t kCulled = cpu::kCulledKey;
    std::vector<std::uint64_t> keys(cloud.size());

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
            std::fill(keys.begin() + begin, keys.begin() + end, kCulled);
            continue;
        }
        if constexpr (std::is_same_v<T, float>) {
            cpu::project_splats(kernel, view, cloud, T(options.alpha_threshold), begin, end, splats.get(),
                                keys.data());
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
    // every tile's list sorted, with no per-tile sort. The walk is split among threads by
    // ranges of the sorted order and each thread writes at offsets fixed by the counts of the
    // threads before it, so the lists do not depend on the number of threads.
    t0 = Clock::now();
    std::vector<std::uint64_t> order = std::move(keys);  // the visible keys, compacted in place
    order.erase(std::remove(order.begin(), order.end(), kCulled), order.end());
    sort_by_depth(order);
    const std::int64_t n_visible = std::int64_t(order.size());
    const std::unique_ptr<SplatRecord<T>[]> sorted(new SplatRecord<T>[order.size()]);
#pragma omp parallel for schedule(static)
    for (std::int64_t k = 0; k < n_visible; ++k) sorted[k] = splats[tiling::key_index(order[k])];
    splats.reset();
    const int tiles_x = tiling::tiles_along(camera.width), tiles_y = tiling::tiles_along(camera.height);
    const std::size_t n_tile_ids = std::size_t(tiles_x) * std::size_t(tiles_y);
    std::vector<std::size_t> offsets(n_tile_ids + 1, 0);
    std::vector<std::uint32_t> lists;  // positions in `sorted`
    const int max_threads = omp_get_max_threads();
    std::vector<std::size_t> cursor(std::size_t(max_threads) * n_tile_ids, 0);
#pragma omp parallel num_threads(max_threads)
    {
        const std::size_t team = std::size_t(omp_get_num_threads()), me = std::size_t(omp_get_thread_num());
        const std::size_t begin = order.size() * me / team, end = order.size() * (me + 1) / team;
        std::size_t* mine = cursor.data() + me * n_tile_ids;
        auto for_each_tile = [tiles_x](const SplatRecord<T>& s, auto&& f) {
            const tiling::TileRect rect = tiling::tile_rect(s.x_min, s.x_max, s.y_min, s.y_max);
            for (int ty = rect.y0; ty < rect.y1; ++ty)
                for (int tx = rect.x0; tx < rect.x1; ++tx) f(std::size_t(ty) * std::size_t(tiles_x) + std::size_t(tx));
        };
        for (std::size_t k = begin; k < end; ++k)
            for_each_tile(sorted[k], [&](std::size_t tile) { ++mine[tile]; });
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
        for (std::size_t k = begin; k < end; ++k)
            for_each_tile(sorted[k], [&](std::size_t tile) { lists[mine[tile]++] = std::uint32_t(k); });
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
        blends += blend_tile_dispatch(kernel, tx, ty, lists.data() + offsets[k], offsets[k + 1] - offsets[k],
                                      sorted.get(), bp, out, contrib ? contrib + offsets[k] : nullptr);
    }
    poll.throw_if_stopped();
    stats.blends = blends;
    if (options.gaussian_contributions) {
        // Tile by tile in tile order (the order of `lists`), whatever thread blended the tile.
        out.has_gaussian_contributions = true;
        out.contribution_max.assign(cloud.size(), 0.0f);
        std::vector<double> sum(cloud.size(), 0.0);
        for (std::size_t j = 0; j < lists.size(); ++j) {
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

template RenderResult render_cpu<float>(const GaussianCloud&, const Camera&, const RenderOptions&);
template RenderResult render_cpu<double>(const GaussianCloud&, const Camera&, const RenderOptions&);

}  // namespace avsplat::detail
