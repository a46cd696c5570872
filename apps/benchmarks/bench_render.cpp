// Benchmark of the CPU splat renderer (not a test).
//
// A synthetic scene of N Gaussians of SH degree 3 (default 500,000) in the cube [-1, 1]^3, with
// random rotations, anisotropic scales log-uniform in [0.003, 0.03], opacities uniform in
// [0.05, 1] and random SH, rendered at W x H (default 1280 x 720) from V viewpoints (default 5)
// on a circle of radius 3.5 around the cube, 50 degrees vertical field of view (bench_scene.h,
// shared with bench_render_cuda).
//
// For each view (best of R runs by CPU time) it prints the wall and CPU time per frame, the
// Gaussian-pixel blends (evaluated pairs, see RenderStats::blends) per second per core, and the
// shares of projection, sorting and blending in the wall time; then the same figures over all
// views, the float64 reference path on the first view as the peer measured in the same run, and
// the first view with RenderOptions::gaussian_contributions (what prune asks for) against colour only,
// and the first view with the portable tile kernel (AVSPLAT_CPU_KERNEL=scalar, the kernel of
// CPUs without AVX2) against the kernel in use. The views are rendered with one
// avsplat::RenderWorkspace (buffers reused between frames), then again without ("fresh": every
// render allocates its buffers, whose new pages the kernel clears). Frames per second are 1 / wall time per frame.
// The last line gives the ratio of the float32 figure to the target (400 M
// blends/s/core).
// Per core is measured as blends per second of process CPU time (all threads together), which
// stays meaningful on a machine shared with other work; the blending stage's own rate is
// blends / (blending wall time x threads).
//
// Usage: bench_render [--gaussians N] [--width W] [--height H] [--views V] [--repeats R]
// Threads: OMP_NUM_THREADS (per-core figures divide by the number of threads used).
// Real-time figure: OMP_NUM_THREADS=2 bench_render --gaussians 1000000.
// Tile kernel: AVSPLAT_CPU_KERNEL=auto|avx512|avx2|scalar (lib/src/render/cpu/cpu_kernel.h).
#include "bench_scene.h"
#include "machine.h"

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"


#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <utility>
#include <vector>

namespace {

struct Totals {
    double total = 0, projection = 0, sorting = 0, blending = 0, cpu = 0;
    double blends = 0, visible = 0, instances = 0;
    int frames = 0;
    void add(const avsplat::RenderStats& s, double cpu_seconds) {
        total += s.seconds_total;
        projection += s.seconds_projection;
        sorting += s.seconds_sorting;
        blending += s.seconds_blending;
        cpu += cpu_seconds;
        blends += double(s.blends);
        visible += double(s.visible);
        instances += double(s.tile_instances);
        ++frames;
    }
};

/// One render and the CPU time it took, all threads together (std::clock is process CPU time).
/// With a workspace, its buffers and the images of the previous result are reused
/// (avsplat::RenderWorkspace, recycle); without, each render allocates its own.
avsplat::RenderStats timed_render(const avsplat::GaussianCloud& cloud, const avsplat::Camera& camera,
                                  const avsplat::RenderOptions& options, double& cpu_seconds,
                                  avsplat::RenderWorkspace* workspace = nullptr) {
    const std::clock_t c0 = std::clock();
    avsplat::RenderStats s;
    if (workspace) {
        avsplat::RenderResult r = avsplat::render(cloud, camera, options, *workspace);
        s = r.stats;
        workspace->recycle(std::move(r));  // its images' memory serves the next frame
    } else {
        s = avsplat::render(cloud, camera, options).stats;
    }
    cpu_seconds = double(std::clock() - c0) / CLOCKS_PER_SEC;
    return s;
}

/// The best of `repeats` renders of one view by CPU time, added to `into` (and to `also`).
void best_render(const avsplat::GaussianCloud& cloud, const avsplat::Camera& camera,
                 const avsplat::RenderOptions& options, int repeats, Totals& into, Totals* also = nullptr,
                 avsplat::RenderWorkspace* workspace = nullptr) {
    avsplat::RenderStats best;
    double best_cpu = 1e300;
    for (int r = 0; r < repeats; ++r) {
        double cpu = 0;
        const avsplat::RenderStats s = timed_render(cloud, camera, options, cpu, workspace);
        if (cpu < best_cpu) {
            best = s;
            best_cpu = cpu;
        }
    }
    into.add(best, best_cpu);
    if (also) also->add(best, best_cpu);
}

void print_row(const char* label, const Totals& t, int threads) {
    std::printf("%-10s %7.1f ms/frame wall (%5.1f frames/s) %7.1f ms CPU  visible %7.0f  instances %8.0f  blends %9.3g  "
                "%6.1f M blends/s/core (CPU time) %6.1f M (blending stage, wall)  "
                "projection %4.1f%%  sorting %4.1f%%  blending %4.1f%%\n",
                label, 1e3 * t.total / t.frames, t.frames / t.total, 1e3 * t.cpu / t.frames, t.visible / t.frames,
                t.instances / t.frames, t.blends / t.frames, 1e-6 * t.blends / t.cpu,
                1e-6 * t.blends / (t.blending * threads), 100.0 * t.projection / t.total,
                100.0 * t.sorting / t.total, 100.0 * t.blending / t.total);
}

}  // namespace

int main(int argc, char** argv) {
    avsplat::bench::SceneArgs args;
    if (!avsplat::bench::parse_scene_args(argc, argv, args)) return 2;
    const std::size_t n = args.gaussians;
    const int width = args.width, height = args.height, views = args.views, repeats = args.repeats;
    const avsplat::GaussianCloud cloud = avsplat::bench::make_scene(n, 7);
    const std::vector<avsplat::Camera> cameras = avsplat::bench::make_views(views, width, height);
    avsplat::RenderOptions options;
    int threads = 1;
    {
        // Warm-up (page faults, thread pool) outside the measurement.
        threads = avsplat::render(cloud, cameras[0], options).stats.threads;
    }
    std::printf("bench_render: %zu Gaussians of SH degree 3, %dx%d, %d views, best of %d runs each "
                "(by CPU time), %d thread%s\n",
                n, width, height, views, repeats, threads, threads == 1 ? "" : "s");
    std::printf("%s\n", avsplat::bench::machine_description(threads).c_str());
    const char* kernel_env = std::getenv("AVSPLAT_CPU_KERNEL");
    const std::string kernel = kernel_env && *kernel_env ? kernel_env : "auto";
    std::printf("tile kernel: AVSPLAT_CPU_KERNEL=%s (auto: AVX-512, else AVX2, where the CPU has it)\n", kernel.c_str());
    // The views with one workspace (what a caller rendering many views does), then the same
    // views with fresh buffers for every render (render() without a workspace).
    avsplat::RenderWorkspace workspace;
    Totals all;
    for (int v = 0; v < views; ++v) {
        Totals one;
        best_render(cloud, cameras[v], options, repeats, one, &all, &workspace);
        print_row(("view " + std::to_string(v)).c_str(), one, threads);
    }
    print_row("all views", all, threads);
    Totals fresh;
    for (int v = 0; v < views; ++v) best_render(cloud, cameras[v], options, repeats, fresh);
    print_row("fresh", fresh, threads);
    std::printf("without a workspace (fresh buffers every frame) a frame takes %.2fx the CPU time, %.2fx the wall "
                "time; the workspace holds %.1f MB\n",
                fresh.cpu / all.cpu, fresh.total / all.total, 1e-6 * double(workspace.bytes()));

    // The peer in the same run: the float64 reference path from the same source, first view.
    options.precision = avsplat::Precision::Float64;
    Totals ref;
    {
        double cpu = 0;
        const avsplat::RenderStats s = timed_render(cloud, cameras[0], options, cpu);
        ref.add(s, cpu);
    }
    print_row("float64 v0", ref, threads);
    Totals first;
    {
        options.precision = avsplat::Precision::Float32;
        double cpu = 0;
        const avsplat::RenderStats s = timed_render(cloud, cameras[0], options, cpu);
        first.add(s, cpu);
    }
    std::printf("float32 takes %.2fx less CPU time than float64 on view 0\n", ref.cpu / first.cpu);

    // What asking for per-Gaussian contributions (prune's input) costs, first view, best of the repeats.
    options.gaussian_contributions = true;
    Totals contrib;
    best_render(cloud, cameras[0], options, repeats, contrib);
    print_row("contrib v0", contrib, threads);
    std::printf("gaussian_contributions costs %.2fx the CPU time of colour only on view 0\n",
                contrib.cpu / first.cpu);

    // The portable tile kernel on the first view, best of the repeats, against the kernel in use.
    options.gaussian_contributions = false;
    setenv("AVSPLAT_CPU_KERNEL", "scalar", 1);
    Totals portable;
    best_render(cloud, cameras[0], options, repeats, portable);
    if (kernel_env) setenv("AVSPLAT_CPU_KERNEL", kernel.c_str(), 1);
    else unsetenv("AVSPLAT_CPU_KERNEL");
    print_row("scalar v0", portable, threads);
    std::printf("the kernel in use (%s) takes %.2fx less CPU time than the portable kernel on view 0\n",
                kernel.c_str(), portable.cpu / first.cpu);
    const double per_core = 1e-6 * all.blends / all.cpu;
    std::printf("float32, all views: %.1f M blends/s/core (CPU time) = %.2fx the target of 400 M; "
                "%.1f frames/s (wall) with %d thread%s\n",
                per_core, per_core / 400.0, all.frames / all.total, threads, threads == 1 ? "" : "s");
    return 0;
}
