// Benchmark of the CPU renderer's projection stage alone (lib/src/render/cpu/project_splats.h;
// not a test), on bench_render's scene and views (bench_scene.h: 500,000 Gaussians of SH degree
// 3, 1280 x 720, 5 views by default), one thread.
//
// For each kernel this CPU has it projects the whole cloud from every view (records, power_cut,
// sort keys, as render_cpu's projection loop does) and prints the CPU time per view, best of R
// runs: into records written before (warm pages), and into a records array allocated for the run
// as render() allocates one per frame ("new"). glibc hands the freed array back to the next
// allocation, so only the first such run of the process (view 0) pays the page faults of fresh
// memory, as only a process's first frame does. Peers in the same run: the portable kernel (the
// scalar project_record, the projection of main before the vector kernels) and a read of the
// input floats the projection reads (means, scales, rotations, opacities, SH: 59 floats a
// Gaussian), the memory-bound floor. The last lines give the ratios to the target of 15 ms per
// view (the projection's share of a 72 ms frame).
//
// Usage: bench_project [--gaussians N] [--width W] [--height H] [--views V] [--repeats R]
#include "bench_scene.h"
#include "machine.h"

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"
#include "render/cpu/blend_tile_avx2.h"
#include "render/cpu/blend_tile_avx512.h"
#include "render/cpu/project_splats.h"
#include "render/shared/view_params.h"

#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <cstdio>
#include <ctime>
#include <memory>
#include <string>
#include <vector>

namespace {

namespace cpu = avsplat::detail::cpu;

double cpu_now() { return double(std::clock()) / CLOCKS_PER_SEC; }

/// CPU seconds of one projection of the whole cloud; `fresh`: into a records array allocated here.
double project_once(cpu::CpuKernel kernel, const avsplat::GaussianCloud& cloud, const avsplat::Camera& cam,
                    const avsplat::RenderOptions& o, bool fresh, std::unique_ptr<cpu::SplatRecord<float>[]>& warm,
                    std::vector<std::uint64_t>& keys, std::size_t& visible) {
    const double t0 = cpu_now();
    const auto view = avsplat::preprocess::view_params<float>(cam, o, cloud.sh_degree);
    std::unique_ptr<cpu::SplatRecord<float>[]> fresh_records;
    cpu::SplatRecord<float>* records = warm.get();
    if (fresh) {
        fresh_records.reset(new cpu::SplatRecord<float>[cloud.size()]);
        records = fresh_records.get();
    }
    cpu::project_splats(kernel, view, cloud, o.alpha_threshold, 0, std::int64_t(cloud.size()), records, keys.data());
    const double t = cpu_now() - t0;
    visible = std::size_t(std::count_if(keys.begin(), keys.end(), [](std::uint64_t k) { return k != cpu::kCulledKey; }));
    return t;
}

/// CPU seconds of a read of the input floats the projection reads: an integer sum of their bits,
/// which the compiler vectorises, so that the read is bound by memory, not by an add chain.
double read_floor(const avsplat::GaussianCloud& c, std::uint32_t& sink) {
    const double t0 = cpu_now();
    std::uint32_t s = 0;
    for (const std::vector<float>* v : {&c.means, &c.scales, &c.rotations, &c.opacities, &c.sh}) {
        const float* p = v->data();
        const std::size_t n = v->size();
        for (std::size_t i = 0; i < n; ++i) {
            std::uint32_t b;
            std::memcpy(&b, p + i, sizeof b);
            s += b;
        }
    }
    sink += s;
    return cpu_now() - t0;
}

}  // namespace

int main(int argc, char** argv) {
    avsplat::bench::SceneArgs args;
    if (!avsplat::bench::parse_scene_args(argc, argv, args)) return 2;
    omp_set_num_threads(1);
    const avsplat::GaussianCloud cloud = avsplat::bench::make_scene(args.gaussians, 7);
    const std::vector<avsplat::Camera> views = avsplat::bench::make_views(args.views, args.width, args.height);
    const avsplat::RenderOptions options;
    std::printf("bench_project: %zu Gaussians of SH degree 3, %dx%d, %d views, best of %d runs each (CPU time), 1 thread\n",
                args.gaussians, args.width, args.height, args.views, args.repeats);
    std::printf("%s\n", avsplat::bench::machine_description(1).c_str());

    std::vector<std::pair<cpu::CpuKernel, const char*>> kernels{{cpu::CpuKernel::Portable, "portable (scalar project_record)"}};
    if (cpu::avx2_kernel_available()) kernels.emplace_back(cpu::CpuKernel::Avx2, "avx2");
    if (cpu::avx512_kernel_available()) kernels.emplace_back(cpu::CpuKernel::Avx512, "avx512");

    std::unique_ptr<cpu::SplatRecord<float>[]> warm(new cpu::SplatRecord<float>[cloud.size()]);
    std::vector<std::uint64_t> keys(cloud.size());
    std::vector<double> mean_warm(kernels.size(), 0.0), mean_fresh(kernels.size(), 0.0);
    std::uint32_t sink = 0;
    double floor_best = 1e30;
    for (int r = 0; r < args.repeats; ++r) floor_best = std::min(floor_best, read_floor(cloud, sink));
    for (std::size_t v = 0; v < views.size(); ++v) {
        std::printf("view %zu", v);
        for (std::size_t k = 0; k < kernels.size(); ++k) {
            double best_warm = 1e30, best_fresh = 1e30;
            std::size_t visible = 0;
            // Alternate warm and fresh runs so both see the same machine minutes.
            for (int r = 0; r < args.repeats; ++r) {
                best_warm = std::min(best_warm, project_once(kernels[k].first, cloud, views[v], options, false, warm, keys, visible));
                best_fresh = std::min(best_fresh, project_once(kernels[k].first, cloud, views[v], options, true, warm, keys, visible));
            }
            mean_warm[k] += best_warm / double(views.size());
            mean_fresh[k] += best_fresh / double(views.size());
            std::printf("  %s %.1f / %.1f ms (visible %zu)", kernels[k].second, 1e3 * best_warm, 1e3 * best_fresh, visible);
        }
        std::printf("\n");
    }
    std::printf("ms CPU per view, all views (warm records / new records array, as a frame; view 0's first run faults its pages in):\n");
    for (std::size_t k = 0; k < kernels.size(); ++k)
        std::printf("  %-34s %6.1f / %6.1f ms  %5.1f ns per Gaussian (new)  %.2fx less than portable (new)  "
                    "%.2fx the 15 ms target (new)\n",
                    kernels[k].second, 1e3 * mean_warm[k], 1e3 * mean_fresh[k], 1e9 * mean_fresh[k] / double(cloud.size()),
                    mean_fresh[0] / mean_fresh[k], 1e3 * mean_fresh[k] / 15.0);
    std::printf("peer: reading the %zu input floats (%.0f MB) takes %.1f ms; the fastest kernel is %.2fx that floor "
                "(new records)%s\n",
                cloud.means.size() + cloud.scales.size() + cloud.rotations.size() + cloud.opacities.size() + cloud.sh.size(),
                4e-6 * double(cloud.means.size() + cloud.scales.size() + cloud.rotations.size() + cloud.opacities.size() +
                              cloud.sh.size()),
                1e3 * floor_best, mean_fresh.back() / floor_best, sink == 12345u ? " " : "");
    return 0;
}
