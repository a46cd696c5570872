// Benchmark of the CUDA splat renderer beside the CPU renderer (not a test).
//
// The scene and views of bench_render (the CPU renderer's benchmark; both use bench_scene.h):
// N Gaussians of SH degree 3 (default 500,000) in [-1, 1]^3 with random rotations, scales
// log-uniform in [0.003, 0.03], opacities in [0.05, 1] and random SH, rendered at W x H (default
// 1280 x 720) from V views (default 5) on a circle of radius 3.5, 50 degrees vertical field of
// view.
//
// For each view and back end it keeps the best of R runs and prints the frame time, the
// Gaussian-pixel blends per second (RenderStats::blends over the whole frame, and over the
// blending stage) and the stage times. Back ends:
//   cpu          render() with Backend::Cpu, all OpenMP threads (OMP_NUM_THREADS);
//   cuda host    render() with Backend::Cuda from the host GaussianCloud: the frame time
//                includes uploading the cloud (about 120 MB at N = 500,000) and allocations;
//   cuda device  render(DeviceGaussians) with the cloud already on the GPU: the frame time
//                includes allocations, device-side validation and copying the images back.
// Both include copying the four images to the host. As a sanity check (not a test) it also
// prints the largest colour difference and the number of pixels whose contributor counts differ
// between CUDA and the CPU for each view, float32.
//
// Usage: bench_render_cuda [--gaussians N] [--width W] [--height H] [--views V] [--repeats R]
// Exit status 3 when no CUDA device is usable.
#include "bench_scene.h"
#include "machine.h"

#include "avsplat/core/camera.h"
#include "avsplat/core/error.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"
#include "avsplat/render/render_cuda.h"

#include <cuda_runtime_api.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <utility>
#include <vector>

namespace {

void cuda_check(cudaError_t e, const char* what) {
    if (e != cudaSuccess) {
        std::fprintf(stderr, "bench_render_cuda: %s: %s\n", what, cudaGetErrorString(e));
        std::exit(1);
    }
}


struct Totals {
    double total = 0, projection = 0, sorting = 0, blending = 0, blends = 0;
    int frames = 0;
    void add(const avsplat::RenderStats& s) {
        total += s.seconds_total;
        projection += s.seconds_projection;
        sorting += s.seconds_sorting;
        blending += s.seconds_blending;
        blends += double(s.blends);
        ++frames;
    }
};

void print_row(const std::string& label, const Totals& t) {
    std::printf("%-22s %9.2f ms/frame  %9.1f M blends/s (frame)  %9.1f M blends/s (blending)  "
                "projection %7.2f ms  sorting %7.2f ms  blending %7.2f ms\n",
                label.c_str(), 1e3 * t.total / t.frames, 1e-6 * t.blends / t.total,
                1e-6 * t.blends / t.blending, 1e3 * t.projection / t.frames,
                1e3 * t.sorting / t.frames, 1e3 * t.blending / t.frames);
}

template <class F>
avsplat::RenderResult best_of(int repeats, F&& run) {
    avsplat::RenderResult best = run();
    for (int r = 1; r < repeats; ++r) {
        avsplat::RenderResult res = run();
        if (res.stats.seconds_total < best.stats.seconds_total) best = std::move(res);
    }
    return best;
}

}  // namespace

int main(int argc, char** argv) {
    avsplat::bench::SceneArgs args;
    if (!avsplat::bench::parse_scene_args(argc, argv, args)) return 2;
    const std::size_t n = args.gaussians;
    const int width = args.width, height = args.height, views = args.views, repeats = args.repeats;
    if (avsplat::cuda_device_count() == 0) {
        int count = 0;
        const cudaError_t e = cudaGetDeviceCount(&count);
        std::fprintf(stderr, "bench_render_cuda: no CUDA device: %s\n",
                     e == cudaSuccess ? "0 devices" : cudaGetErrorString(e));
        return 3;
    }
    int device = 0;
    cudaDeviceProp prop{};
    cuda_check(cudaGetDevice(&device), "cudaGetDevice");
    cuda_check(cudaGetDeviceProperties(&prop, device), "cudaGetDeviceProperties");

    const avsplat::GaussianCloud cloud = avsplat::bench::make_scene(n, 7);
    const std::vector<avsplat::Camera> cameras = avsplat::bench::make_views(views, width, height);
    avsplat::RenderOptions cpu_options, cuda_options;
    cuda_options.backend = avsplat::Backend::Cuda;
    const avsplat::DeviceGaussianCloud device_cloud(cloud);

    // Warm-up outside the measurement: CUDA context and module loading, OpenMP threads.
    const int threads = avsplat::render(cloud, cameras[0], cpu_options).stats.threads;
    avsplat::render(device_cloud.view(), cameras[0], cuda_options);

    std::printf("bench_render_cuda: %zu Gaussians of SH degree 3, %dx%d, %d views, best of %d runs each\n",
                n, width, height, views, repeats);
    std::printf("%s\n", avsplat::bench::machine_description(1).c_str());
    std::printf("GPU: %s (sm_%d%d, %d SMs); CPU: %d OpenMP thread%s\n", prop.name, prop.major, prop.minor,
                prop.multiProcessorCount, threads, threads == 1 ? "" : "s");
    Totals all_cpu, all_host, all_device;
    for (int v = 0; v < views; ++v) {
        const avsplat::RenderResult cpu = best_of(repeats, [&] { return avsplat::render(cloud, cameras[v], cpu_options); });
        const avsplat::RenderResult host = best_of(repeats, [&] { return avsplat::render(cloud, cameras[v], cuda_options); });
        const avsplat::RenderResult dev =
            best_of(repeats, [&] { return avsplat::render(device_cloud.view(), cameras[v], cuda_options); });
        Totals c, h, d;
        c.add(cpu.stats);
        h.add(host.stats);
        d.add(dev.stats);
        all_cpu.add(cpu.stats);
        all_host.add(host.stats);
        all_device.add(dev.stats);
        const std::string view = "view " + std::to_string(v);
        print_row(view + " cpu", c);
        print_row(view + " cuda host", h);
        print_row(view + " cuda device", d);
        double max_color = 0;
        for (std::size_t i = 0; i < cpu.color.size(); ++i)
            max_color = std::max(max_color, double(std::abs(cpu.color[i] - dev.color[i])));
        std::size_t contributor_diff = 0;
        for (std::size_t i = 0; i < cpu.contributors.size(); ++i) contributor_diff += cpu.contributors[i] != dev.contributors[i];
        std::printf("%-22s visible %zu  instances %zu  blends %.4g  max |colour cuda - cpu| %.3g  "
                    "contributor mismatches %zu\n",
                    view.c_str(), dev.stats.visible, dev.stats.tile_instances, double(dev.stats.blends),
                    max_color, contributor_diff);
    }
    print_row("all views cpu", all_cpu);
    print_row("all views cuda host", all_host);
    print_row("all views cuda device", all_device);
    std::printf("CUDA is %.1fx (host arrays) and %.1fx (device arrays) faster than the CPU renderer "
                "(whole frame, all views)\n",
                all_cpu.total / all_host.total, all_cpu.total / all_device.total);
    return 0;
}
