// Benchmark of SparseVoxelGrid and fuse_voxels at growing sample counts (not a test).
//
// Workload (as bench_fusion.py's): N samples uniformly on a unit sphere shell (radius uniform in
// [0.996, 1.004], random order), C feature channels (default 56), a confidence logit per sample
// ~ N(0, 1), voxel 0.01 (about 225k occupied voxels whatever N, so occupancy grows with N as when
// more views of one scene are fused; 16M = 64 views of 512 x 512). The input arrays are
// allocated as numpy allocates large arrays (transparent huge pages advised), so that the figures
// match what the Python API sees (HugePageAllocator).
//
// For each N it prints: the voxel count, the median time (of --repeats) of the grid build alone,
// of fuse_voxels with the occupancy and softmax policies, of a memcpy of the input bytes
// (positions, features, confidence; the bandwidth floor), the ratio occupancy / memcpy, and the
// peak resident memory of the process while fusing (VmHWM after resetting it through
// /proc/self/clear_refs; it includes the input arrays, whose size is printed beside it).
//
// Usage: bench_fusion_scaling [--sizes 2,4,8,16] (millions) [--channels 56] [--voxel 0.01]
//                             [--repeats 3] [--profile CALLS] [--inputs PREFIX] [--floor]
// --profile CALLS: for each size, only fuse_voxels (occupancy) CALLS times after the workload is
// made, printing the median wall and CPU seconds per call: the process to record with perf, its
// samples from the first pack_keys on being the calls alone (docs/benchmarks/fusion.md); it
// also prints the minor page faults per call.
// --inputs PREFIX: instead of making the workload, read N samples from PREFIX.pos (N x 3),
// PREFIX.feat (N x C) and PREFIX.conf (N) float32 files (numpy's tofile; N from --sizes, one
// size), so that C++ and Python fuse the same bytes (the Python benchmark's arrays).
// --floor: for each size, on the calling thread, the memory traffic fusion cannot avoid, each
// timed alone (median of --repeats, CPU seconds): the grid build; the scattered reads of the
// positions and confidences in the grid's sample order (what the weighing must read); the
// scattered reads of the feature rows in that order (what the averaging must read), each with
// the library's prefetching and a plain sum as the only arithmetic; the rows of only the samples
// with a non-zero weight and a sequential finiteness scan of the features (what the averaging
// reads since it skips the rows that trimming leaves out); a memcpy of the input. It
// prints the cache lines each read touches and the rate at which this machine delivers them,
// next to fuse_voxels itself (docs/benchmarks/fusion.md). Run it with OMP_NUM_THREADS=1.
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

// Whether AVSPLAT_BENCH_ALIGN=64 asks for 64-byte aligned inputs.
bool aligned_inputs() {
    static const bool on = [] {
        const char* v = std::getenv("AVSPLAT_BENCH_ALIGN");
        return v && std::string(v) == "64";
    }();
    return on;
}

// std::allocator that places large blocks as numpy does on Linux (glibc malloc: a fresh mapping,
// the data 16 bytes past a page boundary; transparent huge pages advised for its 2 MiB-aligned
// part), so that the figures match what the Python API sees. The placement matters: a 224-byte
// feature row (56 channels) starting 16 bytes into a cache line spans 4.5 lines on average,
// against 4 when rows start on a 64-byte boundary, and the scattered row reads of fusion cost
// 5-10 % more CPU for it (docs/benchmarks/fusion.md). AVSPLAT_BENCH_ALIGN=64 starts the data
// on a 64-byte boundary instead (to measure that difference).
template <class T>
struct HugePageAllocator {
    using value_type = T;
    HugePageAllocator() = default;
    template <class U>
    HugePageAllocator(const HugePageAllocator<U>&) noexcept {}
    T* allocate(std::size_t n) {
        constexpr std::size_t kHuge = std::size_t(1) << 21;
        const std::size_t bytes = n * sizeof(T);
        char* base = static_cast<char*>(std::malloc(bytes + 72));
        if (!base) throw std::bad_alloc();
        char* data = base;
        if (aligned_inputs()) {
            // 64-byte aligned, the block's start kept just before the data for deallocate.
            data = base + ((reinterpret_cast<std::uintptr_t>(base) + 8 + 63) / 64 * 64 - reinterpret_cast<std::uintptr_t>(base));
            std::memcpy(data - sizeof base, &base, sizeof base);
        }
        const std::uintptr_t lo = (reinterpret_cast<std::uintptr_t>(data) + kHuge - 1) / kHuge * kHuge;
        const std::uintptr_t hi = (reinterpret_cast<std::uintptr_t>(data) + bytes) / kHuge * kHuge;
        if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
        return reinterpret_cast<T*>(data);
    }
    void deallocate(T* p, std::size_t) noexcept {
        char* base = reinterpret_cast<char*>(p);
        if (aligned_inputs()) std::memcpy(&base, base - sizeof base, sizeof base);
        std::free(base);
    }
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

// Reads `count` floats of `path` into `out`; exits naming the file when it is shorter.
void read_floats(const std::string& path, std::size_t count, HugeVector<float>& out) {
    out.resize(count);
    std::ifstream f(path, std::ios::binary);
    if (!f.read(reinterpret_cast<char*>(out.data()), std::streamsize(count * sizeof(float)))) {
        std::fprintf(stderr, "bench_fusion_scaling: cannot read %zu floats from %s\n", count, path.c_str());
        std::exit(2);
    }
}

Workload read_workload(const std::string& prefix, std::size_t n, int channels) {
    Workload w;
    w.n = n;
    w.channels = channels;
    read_floats(prefix + ".pos", 3 * n, w.positions);
    read_floats(prefix + ".feat", n * std::size_t(channels), w.features);
    read_floats(prefix + ".conf", n, w.confidence);
    return w;
}

// Median CPU seconds (user + system, all threads) of `repeats` calls of fn, each after `before`
// (untimed).
double cpu_seconds();
double median_cpu_seconds(int repeats, const std::function<void()>& fn, const std::function<void()>& before = [] {}) {
    std::vector<double> t;
    for (int r = 0; r < repeats; ++r) {
        before();
        const double c0 = cpu_seconds();
        fn();
        t.push_back(cpu_seconds() - c0);
    }
    std::sort(t.begin(), t.end());
    return t[t.size() / 2];
}

// Distinct 64-byte lines of [p, p + bytes).
std::size_t lines_of(const void* p, std::size_t bytes) {
    if (bytes == 0) return 0;
    const std::uintptr_t a = reinterpret_cast<std::uintptr_t>(p);
    return (a + bytes - 1) / 64 - a / 64 + 1;
}

// The --floor figures of one workload (see the file comment).
void print_floor(const Workload& w, double voxel, int repeats) {
    const std::size_t n = w.n, ch = std::size_t(w.channels);
    std::vector<std::int32_t> ids;
    std::vector<std::int64_t> offsets;
    const double t_grid = median_cpu_seconds(repeats, [&] {
        avsplat::SparseVoxelGrid g(w.positions.data(), n, voxel);
        if (ids.empty()) {
            ids = g.sample_indices();
            offsets = g.voxel_offsets();
        }
    });
    const float* pos = w.positions.data();
    const float* conf = w.confidence.data();
    const float* feat = w.features.data();
    volatile float sink = 0.f;
    // Each read starts with the caches holding other data (a 64 MiB buffer read and written), as
    // in fusion, where the grid's 50 MB of sort buffers pass between reading the positions and
    // weighing.
    std::vector<char> other(std::size_t(64) << 20, 1);
    const auto evict = [&] {
        for (std::size_t k = 0; k < other.size(); k += 64) other[k] = char(other[k] + 1);
    };
    // Positions and confidences in sample order, prefetched 64 samples ahead into L2 (both lines
    // a 12-byte position may touch), as the weigher does.
    std::size_t point_lines = 0;
    for (std::size_t j = 0; j < n; ++j) {
        const std::size_t i = std::size_t(ids[j]);
        point_lines += lines_of(pos + 3 * i, 12) + lines_of(conf + i, 4);
    }
    const double t_points = median_cpu_seconds(repeats, [&] {
        float acc = 0.f;
        for (std::size_t j = 0; j < n; ++j) {
            if (j + 64 < n) {
                const std::size_t a = std::size_t(ids[j + 64]);
                __builtin_prefetch(pos + 3 * a, 0, 2);
                __builtin_prefetch(pos + 3 * a + 2, 0, 2);
                __builtin_prefetch(conf + a, 0, 2);
            }
            const std::size_t i = std::size_t(ids[j]);
            acc += pos[3 * i] + pos[3 * i + 1] + pos[3 * i + 2] + conf[i];
        }
        sink = acc;
    }, evict);
    // Feature rows in sample order, 24 rows ahead into L2, as the averaging pass does: every
    // sample's row, and only those of the samples with a non-zero weight (a voxel's first
    // `kept`, in decreasing confidence: the rows fuse_voxels reads once a sequential scan has
    // found every row finite).
    const auto rows_time = [&](const std::vector<std::int32_t>& order, std::size_t& lines) {
        lines = 0;
        for (std::int32_t i : order) lines += lines_of(feat + ch * std::size_t(i), ch * sizeof(float));
        return median_cpu_seconds(repeats, [&] {
            typedef float Float4 __attribute__((vector_size(16)));
            Float4 acc = {0.f, 0.f, 0.f, 0.f};
            constexpr std::size_t ahead = 24;
            const std::size_t m = order.size();
            for (std::size_t j = 0; j < m; ++j) {
                if (j + ahead < m) {
                    const char* r = reinterpret_cast<const char*>(feat + ch * std::size_t(order[j + ahead]));
                    const char* end = r + ch * sizeof(float);
                    for (const char* q = r; q < end; q += 64) __builtin_prefetch(q, 0, 2);
                    __builtin_prefetch(end - 1, 0, 2);
                }
                // Four channels at a time (the averaging pass's width), then single channels.
                const float* r = feat + ch * std::size_t(order[j]);
                std::size_t c = 0;
                for (; c + 4 <= ch; c += 4) {
                    Float4 x;
                    std::memcpy(&x, r + c, sizeof x);
                    acc += x;
                }
                for (; c < ch; ++c) acc[0] += r[c];
            }
            sink = acc[0] + acc[1] + acc[2] + acc[3];
        }, evict);
    };
    std::size_t row_lines = 0, kept_lines = 0;
    const double t_rows = rows_time(ids, row_lines);
    std::vector<std::int32_t> kept_ids;
    {
        const auto fused = avsplat::fuse_voxels(pos, n, feat, w.channels, voxel, conf);
        for (std::size_t v = 0; v + 1 < offsets.size(); ++v) {
            std::vector<std::int32_t> vox(ids.begin() + offsets[v], ids.begin() + offsets[v + 1]);
            std::stable_sort(vox.begin(), vox.end(), [&](std::int32_t a, std::int32_t b) { return conf[a] > conf[b]; });
            const std::size_t k = vox.size() == 1 ? 1 : std::size_t(fused.diagnostics.kept[v]);
            kept_ids.insert(kept_ids.end(), vox.begin(), vox.begin() + std::ptrdiff_t(k));
        }
    }
    const double t_kept = rows_time(kept_ids, kept_lines);
    // The sequential finiteness scan of every feature that lets fuse_voxels skip the others.
    const double t_scan = median_cpu_seconds(repeats, [&] {
        std::uint32_t bad = 0;
        for (std::size_t j = 0; j < w.features.size(); ++j) {
            std::uint32_t u;
            std::memcpy(&u, feat + j, sizeof u);
            bad |= std::uint32_t((u & 0x7f800000u) == 0x7f800000u);
        }
        sink = float(bad);
    }, evict);
    (void)sink;
    const std::size_t bytes = (w.positions.size() + w.features.size() + w.confidence.size()) * sizeof(float);
    HugeVector<char> dst(bytes + 64, 1);
    const double t_copy = median_cpu_seconds(repeats, [&] {
        char* d = dst.data();
        std::memcpy(d, pos, w.positions.size() * sizeof(float));
        d += w.positions.size() * sizeof(float);
        std::memcpy(d, feat, w.features.size() * sizeof(float));
        d += w.features.size() * sizeof(float);
        std::memcpy(d, conf, w.confidence.size() * sizeof(float));
    }, evict);
    const double t_fuse = median_cpu_seconds(repeats, [&] {
        auto r = avsplat::fuse_voxels(pos, n, feat, w.channels, voxel, conf);
        if (r.size() == 0) std::abort();
    });
    const double floor = t_grid + t_points + t_rows, floor_kept = t_grid + t_points + t_kept + t_scan;
    std::printf("floor %.0fM x %zu channels (CPU s, median of %d, one thread):\n", double(n) / 1e6, ch, repeats);
    std::printf("| step | CPU s | cache lines (M) | ns per line | GB/s of lines |\n|---|---:|---:|---:|---:|\n");
    const auto row = [](const char* name, double t, double lines) {
        if (lines > 0)
            std::printf("| %s | %.4f | %.2f | %.2f | %.1f |\n", name, t, lines / 1e6, t / lines * 1e9, lines * 64 / t / 1e9);
        else
            std::printf("| %s | %.4f | | | |\n", name, t);
    };
    row("grid build (SparseVoxelGrid)", t_grid, 0);
    row("positions + confidences in sample order", t_points, double(point_lines));
    row("feature rows in sample order", t_rows, double(row_lines));
    row("sum of the three (the floor without arithmetic or outputs, reading every row)", floor, 0);
    std::printf("| feature rows of the %.2fM samples with a non-zero weight | %.4f | %.2f | %.2f | %.1f |\n",
                double(kept_ids.size()) / 1e6, t_kept, double(kept_lines) / 1e6, t_kept / double(kept_lines) * 1e9,
                double(kept_lines) * 64 / t_kept / 1e9);
    row("sequential finiteness scan of the features", t_scan, double(w.features.size()) * 4 / 64);
    row("grid + positions + those rows + the scan (the floor reading only the rows needed)", floor_kept, 0);
    row("memcpy of the input", t_copy, double(bytes) / 64);
    row("fuse_voxels occupancy", t_fuse, 0);
    std::printf("floor / memcpy %.2f (reading only the rows needed %.2f), fuse_voxels / floor %.2f, fuse_voxels / memcpy %.2f\n\n",
                floor / t_copy, floor_kept / t_copy, t_fuse / floor, t_fuse / t_copy);
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

// Minor page faults of the process so far.
double minor_faults() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_minflt);
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
    std::string inputs;
    bool floor_mode = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const bool has_value = i + 1 < argc;
        if (a == "--sizes" && has_value) sizes = parse_list(argv[++i]);
        else if (a == "--channels" && has_value) channels = std::atoi(argv[++i]);
        else if (a == "--voxel" && has_value) voxel = std::atof(argv[++i]);
        else if (a == "--repeats" && has_value) repeats = std::max(1, std::atoi(argv[++i]));
        else if (a == "--profile" && has_value) profile = std::max(1, std::atoi(argv[++i]));
        else if (a == "--inputs" && has_value) inputs = argv[++i];
        else if (a == "--floor") floor_mode = true;
        else {
            std::fprintf(stderr, "usage: %s [--sizes 2,4,8,16] [--channels 56] [--voxel 0.01] [--repeats 3] [--profile CALLS] [--inputs PREFIX] [--floor]\n", argv[0]);
            return 2;
        }
    }
    std::printf("bench_fusion_scaling: unit sphere shell, %d channels, voxel %g, %d threads, median of %d\n\n",
                channels, voxel, omp_get_max_threads(), repeats);
    std::printf("%s\n\n", avsplat::bench::machine_description(omp_get_max_threads()).c_str());
    if (profile == 0 && !floor_mode) {
        std::printf("| samples | voxels | grid s | occupancy s | softmax s | memcpy s | occupancy/memcpy | input MiB | peak RSS MiB |\n");
        std::printf("|--------:|-------:|-------:|------------:|----------:|---------:|-----------------:|----------:|-------------:|\n");
    }
    for (double millions : sizes) {
        const std::size_t n = std::size_t(millions * 1e6);
        Workload w = inputs.empty() ? make_workload(n, channels) : read_workload(inputs, n, channels);
        if (floor_mode) {
            print_floor(w, voxel, repeats);
            continue;
        }
        if (profile > 0) {
            std::vector<double> wall, cpu, faults;
            for (int k = 0; k < profile; ++k) {
                const double f0 = minor_faults();
                const double c0 = cpu_seconds();
                const auto t0 = std::chrono::steady_clock::now();
                auto r = avsplat::fuse_voxels(w.positions.data(), n, w.features.data(), channels, voxel,
                                              w.confidence.data());
                wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
                cpu.push_back(cpu_seconds() - c0);
                faults.push_back(minor_faults() - f0);
            }
            std::sort(wall.begin(), wall.end());
            std::sort(cpu.begin(), cpu.end());
            std::sort(faults.begin(), faults.end());
            std::printf("profile %.0fM: fuse_voxels occupancy x %d, median %.4f s wall, %.4f s CPU, %.0f minor faults per call\n",
                        millions, profile, wall[wall.size() / 2], cpu[cpu.size() / 2], faults[faults.size() / 2]);
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
