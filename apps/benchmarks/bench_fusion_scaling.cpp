// Benchmark of SparseVoxelGrid and fuse_voxels at growing sample counts (not a test).
//
// Workload (the issue's): N samples uniformly on a unit sphere shell (radius uniform in
// [0.996, 1.004], random order), C feature channels (default 56), a confidence logit per sample
// ~ N(0, 1), voxel 0.01 (about 225k occupied voxels whatever N, so occupancy grows with N as when
// more views of one scene are fused; 16M = 64 views of 512 x 512). The input arrays are
// allocated as numpy allocates large arrays (transparent huge pages advised), so that the figures
// match what the Python API sees.
//
// For each N it prints: the voxel count, the median time (of --repeats) of the grid build alone,
// of fuse_voxels with the occupancy and softmax policies, of a memcpy of the input bytes
// (positions, features, confidence; the bandwidth floor), the ratio occupancy / memcpy, and the
// peak resident memory of the process while fusing (VmHWM after resetting it through
// /proc/self/clear_refs; it includes the input arrays, whose size is printed beside it).
//
// Usage: bench_fusion_scaling [--sizes 2,4,8,16] (millions) [--channels 56] [--voxel 0.01]
//                             [--repeats 3] [--profile CALLS]
// --profile CALLS: for each size, only fuse_voxels (occupancy) CALLS times after the workload is
// made, printing the median wall and CPU seconds per call: the process to record with perf, its
// samples from the first pack_keys on being the calls alone (RESULTS_fusion.md, issue 18).
// Threads: OMP_NUM_THREADS.
#include "machine.h"

#include "avsplat/fusion/fusion.h"
#include "avsplat/fusion/voxel_grid.h"

#include <omp.h>
#include <sys/mman.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <new>
#include <sstream>
#include <string>
#include <vector>

namespace {

// splitmix64: a fast, seedable generator so that 16M x 56 inputs are made in seconds, in
// parallel, identically for any thread count.
std::uint64_t splitmix(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}
double uniform01(std::uint64_t key) { return double(splitmix(key) >> 11) * 0x1.0p-53; }
double normal(std::uint64_t key) {
    const double u = std::max(uniform01(2 * key), 1e-300), v = uniform01(2 * key + 1);
    return std::sqrt(-2.0 * std::log(u)) * std::cos(6.283185307179586 * v);
}

// std::allocator with transparent huge pages advised for large blocks, as numpy does (Linux).
template <class T>
struct HugePageAllocator {
    using value_type = T;
    HugePageAllocator() = default;
    template <class U>
    HugePageAllocator(const HugePageAllocator<U>&) noexcept {}
    T* allocate(std::size_t n) {
        constexpr std::size_t kHuge = std::size_t(1) << 21;
        const std::size_t bytes = (n * sizeof(T) + kHuge - 1) / kHuge * kHuge;
        void* p = std::aligned_alloc(kHuge, bytes);
        if (!p) throw std::bad_alloc();
        madvise(p, bytes, MADV_HUGEPAGE);
        return static_cast<T*>(p);
    }
    void deallocate(T* p, std::size_t) noexcept { std::free(p); }
    template <class U>
    bool operator==(const HugePageAllocator<U>&) const noexcept { return true; }
    template <class U>
    bool operator!=(const HugePageAllocator<U>&) const noexcept { return false; }
};
template <class T>
using HugeVector = std::vector<T, HugePageAllocator<T>>;

struct Workload {
    std::size_t n = 0;
    int channels = 0;
    HugeVector<float> positions, features, confidence;
};

Workload make_workload(std::size_t n, int channels) {
    Workload w;
    w.n = n;
    w.channels = channels;
    w.positions.resize(3 * n);
    w.features.resize(n * std::size_t(channels));
    w.confidence.resize(n);
#pragma omp parallel for schedule(static)
    for (std::int64_t ii = 0; ii < std::int64_t(n); ++ii) {
        const std::uint64_t i = std::uint64_t(ii);
        double d[3] = {normal(8 * i), normal(8 * i + 1), normal(8 * i + 2)};
        const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + 1e-300;
        const double r = 0.996 + 0.008 * uniform01(8 * i + 3);
        for (int a = 0; a < 3; ++a) w.positions[3 * i + a] = float(d[a] / len * r);
        w.confidence[i] = float(normal(8 * i + 4));
        float* f = &w.features[i * std::size_t(channels)];
        for (int c = 0; c < channels; ++c)
            f[c] = float(uniform01((i << 8) ^ std::uint64_t(c) ^ 0xABCDEFull) * 2.0 - 1.0);
    }
    return w;
}

double median_seconds(int repeats, const std::function<void()>& fn) {
    std::vector<double> t;
    for (int r = 0; r < repeats; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        fn();
        t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
}

bool reset_peak_rss() {
    std::ofstream f("/proc/self/clear_refs");
    if (!f) return false;
    f << "5";
    return bool(f);
}

// Peak resident set in MiB: VmHWM (resettable), else the lifetime peak from getrusage.
double peak_rss_mib() {
    std::ifstream f("/proc/self/status");
    std::string line;
    while (std::getline(f, line)) {
        if (line.rfind("VmHWM:", 0) == 0) {
            std::istringstream is(line.substr(6));
            double kb = 0;
            is >> kb;
            return kb / 1024.0;
        }
    }
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_maxrss) / 1024.0;
}

// CPU seconds of the process, all threads (user + system).
double cpu_seconds() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

std::vector<double> parse_list(const std::string& s) {
    std::vector<double> out;
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, ',')) out.push_back(std::stod(item));
    return out;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<double> sizes = {2, 4, 8, 16};
    int channels = 56, repeats = 3, profile = 0;
    double voxel = 0.01;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const bool has_value = i + 1 < argc;
        if (a == "--sizes" && has_value) sizes = parse_list(argv[++i]);
        else if (a == "--channels" && has_value) channels = std::atoi(argv[++i]);
        else if (a == "--voxel" && has_value) voxel = std::atof(argv[++i]);
        else if (a == "--repeats" && has_value) repeats = std::max(1, std::atoi(argv[++i]));
        else if (a == "--profile" && has_value) profile = std::max(1, std::atoi(argv[++i]));
        else {
            std::fprintf(stderr, "usage: %s [--sizes 2,4,8,16] [--channels 56] [--voxel 0.01] [--repeats 3] [--profile CALLS]\n", argv[0]);
            return 2;
        }
    }
    std::printf("bench_fusion_scaling: unit sphere shell, %d channels, voxel %g, %d threads, median of %d\n\n",
                channels, voxel, omp_get_max_threads(), repeats);
    std::printf("%s\n\n", avsplat::bench::machine_description(omp_get_max_threads()).c_str());
    if (profile == 0) {
        std::printf("| samples | voxels | grid s | occupancy s | softmax s | memcpy s | occupancy/memcpy | input MiB | peak RSS MiB |\n");
        std::printf("|--------:|-------:|-------:|------------:|----------:|---------:|-----------------:|----------:|-------------:|\n");
    }
    for (double millions : sizes) {
        const std::size_t n = std::size_t(millions * 1e6);
        Workload w = make_workload(n, channels);
        if (profile > 0) {
            std::vector<double> wall, cpu;
            for (int k = 0; k < profile; ++k) {
                const double c0 = cpu_seconds();
                const auto t0 = std::chrono::steady_clock::now();
                auto r = avsplat::fuse_voxels(w.positions.data(), n, w.features.data(), channels, voxel,
                                              w.confidence.data());
                wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
                cpu.push_back(cpu_seconds() - c0);
            }
            std::sort(wall.begin(), wall.end());
            std::sort(cpu.begin(), cpu.end());
            std::printf("profile %.0fM: fuse_voxels occupancy x %d, median %.4f s wall, %.4f s CPU per call\n",
                        millions, profile, wall[wall.size() / 2], cpu[cpu.size() / 2]);
            continue;
        }
        const double input_mib =
            double((w.positions.size() + w.features.size() + w.confidence.size()) * sizeof(float)) / (1 << 20);

        const bool resettable = reset_peak_rss();
        std::size_t voxels = 0;
        const double t_grid = median_seconds(repeats, [&] {
            avsplat::SparseVoxelGrid g(w.positions.data(), n, voxel);
            voxels = g.num_voxels();
        });
        avsplat::FusionParams occ;
        const double t_occ = median_seconds(repeats, [&] {
            auto r = avsplat::fuse_voxels(w.positions.data(), n, w.features.data(), channels, voxel,
                                          w.confidence.data(), occ);
            if (r.size() != voxels) std::abort();
        });
        avsplat::FusionParams soft;
        soft.policy = avsplat::FusionPolicy::Softmax;
        const double t_soft = median_seconds(repeats, [&] {
            auto r = avsplat::fuse_voxels(w.positions.data(), n, w.features.data(), channels, voxel,
                                          w.confidence.data(), soft);
            if (r.size() != voxels) std::abort();
        });
        const double peak = peak_rss_mib();

        // The floor: copying the input bytes once, into a buffer touched beforehand.
        HugeVector<char> dst(std::size_t(input_mib * (1 << 20)) + 64, 1);
        const double t_copy = median_seconds(repeats, [&] {
            char* d = dst.data();
            std::memcpy(d, w.positions.data(), w.positions.size() * sizeof(float));
            d += w.positions.size() * sizeof(float);
            std::memcpy(d, w.features.data(), w.features.size() * sizeof(float));
            d += w.features.size() * sizeof(float);
            std::memcpy(d, w.confidence.data(), w.confidence.size() * sizeof(float));
        });
        std::printf("| %.0fM | %zu | %.4f | %.4f | %.4f | %.4f | %.2f | %.0f | %.0f%s |\n", millions, voxels,
                    t_grid, t_occ, t_soft, t_copy, t_occ / t_copy, input_mib, peak, resettable ? "" : " (lifetime)");
        std::fflush(stdout);
    }
    return 0;
}
