#include "avsplat/core/interrupt.h"

#include "avsplat/fusion/fusion.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/sog.h"
#include "avsplat/io/spz.h"
#include "avsplat/point_maps/point_maps.h"
#include "avsplat/render/render.h"

#include <catch2/catch.hpp>

#include <omp.h>

#include <chrono>
#include <dirent.h>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>

using namespace avsplat;
using std::chrono::nanoseconds;

namespace {

GaussianCloud random_cloud(std::size_t n, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    GaussianCloud c(n, 1);
    for (std::size_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            c.means[3 * i + a] = u(rng) - 0.5f + (a == 2 ? 3.f : 0.f);
            c.scales[3 * i + a] = 0.01f + 0.05f * u(rng);
        }
        c.opacities[i] = 0.2f + 0.7f * u(rng);
        for (std::size_t k = 0; k < 12; ++k) c.sh[12 * i + k] = u(rng) - 0.5f;
    }
    return c;
}

std::string read_all(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    std::ostringstream s;
    s << f.rdbuf();
    return s.str();
}

// The files in `dir` whose name starts with `prefix`.
int files_starting_with(const std::string& dir, const std::string& prefix) {
    int count = 0;
    if (DIR* d = opendir(dir.c_str())) {
        while (dirent* e = readdir(d)) count += std::string(e->d_name).rfind(prefix, 0) == 0;
        closedir(d);
    }
    return count;
}

}  // namespace

TEST_CASE("interrupt: a check that says stop makes long calls throw Interrupted", "[interrupt]") {
    const GaussianCloud cloud = random_cloud(20000, 1);
    const Camera cam(300, 300, 64, 48, 128, 96);
    int calls = 0;
    auto stop = [&calls] {
        ++calls;
        return true;
    };
    {
        ScopedInterruptCheck check(stop, nanoseconds(0));
        CHECK_THROWS_AS(fuse_gaussians(cloud, 0.01), Interrupted);
        CHECK(calls >= 1);
        const int before = calls;
        CHECK_THROWS_AS(fuse_voxels(cloud.means.data(), cloud.size(), cloud.sh.data(), 12, 0.01), Interrupted);
        CHECK_THROWS_AS(render(cloud, cam), Interrupted);
        PointMaps maps;
        maps.views = 1;
        maps.height = 1;
        maps.width = int(cloud.size());
        maps.points = cloud.means.data();
        maps.colors = cloud.means.data();
        CHECK_THROWS_AS(gaussians_from_point_maps(maps), Interrupted);
        CHECK(calls >= before + 3);
        // A check that throws counts as "stop".
        ScopedInterruptCheck throwing([]() -> bool { throw std::runtime_error("x"); }, nanoseconds(0));
        CHECK_THROWS_AS(render(cloud, cam), Interrupted);
    }
    // Without a check (the previous one is gone with its scope) the calls run.
    CHECK_NOTHROW(fuse_gaussians(cloud, 0.01));
}

TEST_CASE("interrupt: a check that never stops changes no result", "[interrupt]") {
    const GaussianCloud cloud = random_cloud(20000, 2);
    const Camera cam(300, 300, 64, 48, 128, 96);
    const GaussianFusionResult plain = fuse_gaussians(cloud, 0.02);
    const RenderResult plain_image = render(cloud, cam);
    int calls = 0;
    ScopedInterruptCheck check(
        [&calls] {
            ++calls;
            return false;
        },
        nanoseconds(0));
    const GaussianFusionResult checked = fuse_gaussians(cloud, 0.02);
    const RenderResult checked_image = render(cloud, cam);
    CHECK(calls > 0);
    CHECK(checked.cloud.means == plain.cloud.means);
    CHECK(checked.cloud.sh == plain.cloud.sh);
    CHECK(checked_image.color == plain_image.color);
}

TEST_CASE("interrupt: an interrupted writer leaves the destination as it was", "[interrupt]") {
    const std::string dir = AVSPLAT_TEST_TMP;
    const std::string path = dir + "/interrupted.ply";
    { std::ofstream(path) << "the user's file"; }
    const GaussianCloud cloud = random_cloud(100, 3);
    {
        ScopedInterruptCheck check([] { return true; }, nanoseconds(0));
        CHECK_THROWS_AS(write_ply(path, cloud), Interrupted);
        CHECK_THROWS_AS(throw_if_interrupted(), Interrupted);
    }
    CHECK(read_all(path) == "the user's file");
    CHECK(files_starting_with(dir, ".interrupted.ply.") == 0);  // no temporary file left behind
    CHECK_NOTHROW(throw_if_interrupted());
    write_ply(path, cloud);
    CHECK(read_all(path).rfind("ply\n", 0) == 0);
}

namespace {

// Runs f under a check (interval 0) that counts its calls and says stop from call `stop_at` on
// (never when 0); returns the calls and whether f threw Interrupted.
template <class F>
std::pair<int, bool> counted(int stop_at, const F& f) {
    int calls = 0;
    ScopedInterruptCheck check(
        [&] {
            ++calls;
            return stop_at > 0 && calls >= stop_at;
        },
        nanoseconds(0));
    try {
        f();
    } catch (const Interrupted&) {
        return {calls, true};
    }
    return {calls, false};
}

GaussianCloud sh3_cloud(std::size_t n, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    GaussianCloud c(n, 3);
    for (std::size_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            c.means[3 * i + a] = 4.f * u(rng) - 2.f;
            c.scales[3 * i + a] = 0.01f + 0.05f * u(rng);
        }
        for (int a = 0; a < 4; ++a) c.rotations[4 * i + a] = u(rng) - 0.5f;
        c.opacities[i] = u(rng);
        for (std::size_t k = 0; k < 48; ++k) c.sh[48 * i + k] = u(rng) - 0.5f;
    }
    return c;
}

}  // namespace

TEST_CASE("interrupt: the renderer's sort and binning poll in proportion to their records", "[interrupt]") {
    // One thread, so that every poll runs on the calling thread: projection polls once per 256
    // Gaussians, and each pass over the sorted records must too (they took seconds at 1080p).
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const GaussianCloud cloud = random_cloud(60000, 4);
    const Camera cam(300, 300, 64, 48, 128, 96);
    const RenderResult plain = render(cloud, cam);
    const auto [calls, stopped] = counted(0, [&] { render(cloud, cam); });
    const std::size_t tiles = 8 * 6;
    CHECK_FALSE(stopped);
    REQUIRE(plain.stats.visible > 50000);
    CHECK(std::size_t(calls) >= cloud.size() / 256 + 2 * (plain.stats.visible / 256) + tiles);
    // A stop asked for after projection is honoured before compositing.
    const auto [at, interrupted] = counted(int(cloud.size() / 256) + 3, [&] { render(cloud, cam); });
    CHECK(interrupted);
    CHECK(std::size_t(at) < cloud.size() / 256 + 2 * (plain.stats.visible / 256));
    omp_set_num_threads(threads);
}

TEST_CASE("interrupt: writers poll while they encode, not only at commit", "[interrupt]") {
    const std::string dir = AVSPLAT_TEST_TMP;
    const GaussianCloud cloud = sh3_cloud(100000, 5);
    struct Writer {
        const char* name;
        std::function<void(const std::string&)> write;
        int min_polls;
    };
    SpzWriteOptions v3;
    v3.version = 3;
    SogWriteOptions sog;
    sog.iterations = 2;
    const std::vector<Writer> writers = {
        {"interrupt-poll.ply", [&](const std::string& p) { write_ply(p, cloud); }, 4},
        {"interrupt-poll.spz", [&](const std::string& p) { write_spz(p, cloud); }, 5},
        {"interrupt-poll-v3.spz", [&](const std::string& p) { write_spz(p, cloud, v3); }, 20},
        {"interrupt-poll.sog", [&](const std::string& p) { write_sog(p, cloud, sog); }, 10},
    };
    for (const Writer& w : writers) {
        const std::string path = dir + "/" + w.name;
        INFO(w.name);
        const auto [calls, stopped] = counted(0, [&] { w.write(path); });
        CHECK_FALSE(stopped);
        CHECK(calls >= w.min_polls);
        { std::ofstream(path) << "the user's file"; }
        const auto [at, interrupted] = counted(2, [&] { w.write(path); });
        CHECK(interrupted);
        CHECK(at == 2);
        CHECK(read_all(path) == "the user's file");
    }
}
