#include "avsplat/core/interrupt.h"

#include "avsplat/fusion/fusion.h"
#include "avsplat/io/ply.h"
#include "avsplat/point_maps/point_maps.h"
#include "avsplat/render/render.h"

#include <catch2/catch.hpp>

#include <chrono>
#include <dirent.h>
#include <fstream>
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
