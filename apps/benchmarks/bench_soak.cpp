// Soak benchmark (not a test): fuse and render many times in one process and watch resident
// memory and open file descriptors. A leak of a few hundred bytes per call, invisible in any
// single test, shows up here as steady growth.
//
//   bench_soak [--calls 10000] [--views 4] [--width 48] [--height 36] [--io-every 10]
//
// Scene: the simulator's default scene, `views` input views of width x height predictions
// (one Gaussian per valid pixel); each call fuses them with the occupancy policy (voxel 0.02)
// and renders the fused cloud from the first held-out camera. Every `io_every`-th call also
// writes and reads the fused cloud as PLY and the diagnostics as .npz (AtomicFile, libzip), so
// that a leaked file handle or zip handle would show. Resident memory (VmRSS, /proc/self/status)
// and open descriptors (/proc/self/fd) are sampled after a warm-up of 1% of the calls (at least
// 50) and then every 10%; growth per call is the least-squares slope over those samples, which a
// single late allocation (the allocator's arena growing once) does not dominate. Prints the CPU
// model, cores, threads and load average beside the figures.
#include "avsplat/core/error.h"
#include "avsplat/fusion/fusion.h"
#include "avsplat/io/npz.h"
#include "avsplat/io/ply.h"
#include "avsplat/render/render.h"
#include "avsplat/sim/simulator.h"

#include <dirent.h>
#include <omp.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct Args {
    long calls = 10000;
    int views = 4, width = 48, height = 36;
    long io_every = 10;
};

bool parse(int argc, char** argv, Args& a) {
    for (int k = 1; k + 1 < argc; k += 2) {
        const std::string key = argv[k];
        const long v = std::strtol(argv[k + 1], nullptr, 10);
        if (key == "--calls") a.calls = v;
        else if (key == "--views") a.views = int(v);
        else if (key == "--width") a.width = int(v);
        else if (key == "--height") a.height = int(v);
        else if (key == "--io-every") a.io_every = v;
        else {
            std::fprintf(stderr, "unknown option %s\n", key.c_str());
            return false;
        }
    }
    return a.calls > 0 && a.io_every > 0;
}

long rss_kib() {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.compare(0, 6, "VmRSS:") == 0) return std::strtol(line.c_str() + 6, nullptr, 10);
    return -1;
}

int open_fds() {
    DIR* d = opendir("/proc/self/fd");
    if (!d) return -1;
    int n = 0;
    while (readdir(d)) ++n;
    closedir(d);
    return n - 3;  // ".", ".." and the descriptor of the listing itself
}

std::string first_line_with(const char* path, const char* prefix) {
    std::ifstream in(path);
    std::string line;
    while (std::getline(in, line))
        if (line.compare(0, std::string(prefix).size(), prefix) == 0) return line;
    return "";
}

std::string load_average() {
    std::ifstream in("/proc/loadavg");
    std::string a, b, c;
    in >> a >> b >> c;
    return a + " " + b + " " + c;
}

// Least-squares slope of y over x.
double slope(const std::vector<double>& x, const std::vector<double>& y) {
    double mx = 0, my = 0;
    for (std::size_t i = 0; i < x.size(); ++i) mx += x[i], my += y[i];
    mx /= double(x.size());
    my /= double(y.size());
    double sxy = 0, sxx = 0;
    for (std::size_t i = 0; i < x.size(); ++i) sxy += (x[i] - mx) * (y[i] - my), sxx += (x[i] - mx) * (x[i] - mx);
    return sxx > 0 ? sxy / sxx : 0.0;
}

}  // namespace

int main(int argc, char** argv) {
    Args a;
    if (!parse(argc, argv, a)) return 2;
    avsplat::SimulatorOptions o;
    o.views = a.views;
    o.width = a.width;
    o.height = a.height;
    o.target_views = 1;
    const avsplat::Predictions pred = avsplat::simulate_predictions(o);
    const avsplat::GaussianCloud samples = pred.gaussians();
    const avsplat::Camera camera = pred.target_cameras.at(0);
    avsplat::FusionParams params;
    const std::string dir = std::string(std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "/tmp");
    const std::string ply = dir + "/avsplat_soak_" + std::to_string(getpid()) + ".ply";
    const std::string npz = dir + "/avsplat_soak_" + std::to_string(getpid()) + ".npz";

    std::string cpu = first_line_with("/proc/cpuinfo", "model name");
    cpu = cpu.substr(cpu.find(':') == std::string::npos ? 0 : cpu.find(':') + 2);
    std::printf("bench_soak: %ld calls of fuse_gaussians + render (%zu samples, %d x %d image), I/O every %ld\n",
                a.calls, samples.size(), camera.width, camera.height, a.io_every);
    std::printf("CPU: %s; %ld cores online; %d OpenMP threads; load average before: %s\n", cpu.c_str(),
                sysconf(_SC_NPROCESSORS_ONLN), omp_get_max_threads(), load_average().c_str());

    const long warm = std::max<long>(50, a.calls / 100), step = std::max<long>(1, a.calls / 10);
    std::vector<double> at, rss, fds;
    std::size_t fused_size = 0, checksum = 0;
    const auto t0 = std::chrono::steady_clock::now();
    std::printf("%10s %12s %10s %10s\n", "call", "VmRSS KiB", "open fds", "s");
    for (long call = 1; call <= a.calls; ++call) {
        const avsplat::GaussianFusionResult fused = avsplat::fuse_gaussians(samples, 0.02, params);
        const avsplat::RenderResult image = avsplat::render(fused.cloud, camera);
        fused_size = fused.cloud.size();
        checksum += std::size_t(image.contributors.empty() ? 0 : image.contributors[image.contributors.size() / 2]);
        if (call % a.io_every == 0) {
            avsplat::write_ply(ply, fused.cloud);
            checksum += avsplat::read_ply(ply).size();
            avsplat::write_npz(npz, {avsplat::NpyArray::from_data("temperature", {fused.diagnostics.temperature.size()},
                                                                   fused.diagnostics.temperature.data())},
                               avsplat::NpzCompression::Deflated);
            checksum += avsplat::read_npz(npz).size();
        }
        if (call == warm || (call > warm && (call - warm) % step == 0) || call == a.calls) {
            const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            at.push_back(double(call));
            rss.push_back(double(rss_kib()));
            fds.push_back(double(open_fds()));
            std::printf("%10ld %12.0f %10.0f %10.1f\n", call, rss.back(), fds.back(), s);
            std::fflush(stdout);
        }
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::remove(ply.c_str());
    std::remove(npz.c_str());
    std::printf("fused Gaussians per call: %zu (checksum %zu)\n", fused_size, checksum);
    std::printf("time: %.2f ms per call (%.1f s in all)\n", 1e3 * seconds / double(a.calls), seconds);
    std::printf("VmRSS after warm-up (call %ld): %.0f KiB; at the end: %.0f KiB; growth %.0f KiB\n", warm,
                rss.front(), rss.back(), rss.back() - rss.front());
    std::printf("RSS growth per call (least-squares slope after warm-up): %.2f bytes\n", 1024.0 * slope(at, rss));
    std::printf("open file descriptors: %.0f after warm-up, %.0f at the end\n", fds.front(), fds.back());
    std::printf("load average after: %s\n", load_average().c_str());
    return 0;
}
