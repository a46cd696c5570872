// Per-Gaussian contributions of the CPU renderer (render.h, RenderOptions::gaussian_contributions)
// against a brute-force compositor in double (reference/composite_reference.h): the maximum and
// the sum over pixels of alpha T, the colour-only path untouched, thread-count independence and
// stiff scenes.
#include "avsplat/core/error.h"
#include "avsplat/render/render.h"
#include "reference/composite_reference.h"
#include "reference/reduction_scenes.h"

#include <catch2/catch.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <random>

using namespace avsplat;

namespace {

RenderOptions contribution_options(Precision p) {
    RenderOptions o;
    o.precision = p;
    o.gaussian_contributions = true;
    return o;
}

/// max |a - b| / max(|b|, floor) over the entries.
double max_rel(const std::vector<float>& a, const std::vector<double>& b, double floor) {
    REQUIRE(a.size() == b.size());
    double e = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) e = std::max(e, std::abs(double(a[i]) - b[i]) / std::max(std::abs(b[i]), floor));
    return e;
}

}  // namespace

TEST_CASE("gaussian contributions match a brute-force compositor", "[render][contributions]") {
    std::mt19937 rng(7);
    for (std::uint32_t seed = 0; seed < 6; ++seed) {
        const GaussianCloud cloud = test::reduction_scene(300, int(seed % 4), seed);
        const Camera cam = test::reduction_camera(rng, 53, 37);  // not a multiple of the tile size
        const test::CompositeReference ref = test::composite_reference(cloud, cam, contribution_options(Precision::Float64));
        const RenderResult r64 = render(cloud, cam, contribution_options(Precision::Float64));
        REQUIRE(r64.has_gaussian_contributions);
        REQUIRE(r64.contribution_max.size() == cloud.size());
        // The same operations per pixel in double, rounded to float32 on output.
        CHECK(max_rel(r64.contribution_max, ref.contrib_max, 1e-30) <= 1e-7);
        CHECK(max_rel(r64.contribution_sum, ref.contrib_sum, 1e-30) <= 1e-7);
        // Zero exactly where the reference is zero: the rule prune relies on.
        std::size_t zeros = 0;
        for (std::size_t i = 0; i < cloud.size(); ++i) {
            CHECK((r64.contribution_max[i] == 0.0f) == (ref.contrib_max[i] == 0.0));
            zeros += ref.contrib_max[i] == 0.0;
        }
        CHECK(zeros > 0);              // the scenes have invisible Gaussians ...
        CHECK(zeros < cloud.size());   // ... and visible ones
        // float32: the per-pixel alpha T in float, partial sums per tile in float.
        const RenderResult r32 = render(cloud, cam, contribution_options(Precision::Float32));
        CHECK(max_rel(r32.contribution_max, ref.contrib_max, 1e-3) <= 1e-4);
        CHECK(max_rel(r32.contribution_sum, ref.contrib_sum, 1e-3) <= 1e-4);
        // The colour image is the one of the colour-only path, bit for bit.
        RenderOptions plain;
        const RenderResult c32 = render(cloud, cam, plain);
        CHECK(c32.color == r32.color);
        CHECK(c32.alpha == r32.alpha);
        CHECK(c32.contributors == r32.contributors);
        CHECK_FALSE(c32.has_gaussian_contributions);
        CHECK(c32.contribution_max.empty());
        CHECK(c32.contribution_sum.empty());
    }
}

TEST_CASE("gaussian contributions: the stopping splat counts, later ones do not", "[render][contributions]") {
    // Four Gaussians stacked on the axis, seen at their centre: opacities 0.9 and 0.95 blend
    // (T 1 -> 0.1 -> 0.005); alpha 0.99 would take T to 5e-5 < 1e-4, so that splat stops the
    // pixel (c = 0.99 * 0.005, not blended); the last is never reached.
    GaussianCloud c(4, 0);
    const float opacity[4] = {0.9f, 0.95f, 1.0f, 1.0f};
    for (int i = 0; i < 4; ++i) {
        c.means[3 * i + 2] = float(2.0 + i);
        for (int j = 0; j < 3; ++j) c.scales[3 * i + j] = 0.5f;
        c.opacities[i] = opacity[i];
    }
    const Camera cam(20.0, 20.0, 0.5, 0.5, 1, 1);  // one pixel, its centre on the axis
    for (const Precision p : {Precision::Float64, Precision::Float32}) {
        const RenderResult r = render(c, cam, contribution_options(p));
        CHECK(r.contribution_max[0] == Approx(0.9).epsilon(1e-6));
        CHECK(r.contribution_max[1] == Approx(0.95 * 0.1).epsilon(1e-5));
        CHECK(r.contribution_max[2] == Approx(0.99 * 0.005).epsilon(1e-4));
        CHECK(r.contribution_max[3] == 0.0f);
        CHECK(r.contribution_sum == r.contribution_max);  // one pixel
        CHECK(r.contributors[0] == 2);
    }
}

TEST_CASE("gaussian contributions do not depend on the number of threads", "[render][contributions]") {
    std::mt19937 rng(3);
    const GaussianCloud cloud = test::reduction_scene(2000, 1, 11, 0.3, 0.02, 0.6);
    const Camera cam = test::reduction_camera(rng, 160, 120);
    const int before = omp_get_max_threads();
    omp_set_num_threads(1);
    const RenderResult one = render(cloud, cam, contribution_options(Precision::Float32));
    omp_set_num_threads(4);
    const RenderResult four = render(cloud, cam, contribution_options(Precision::Float32));
    omp_set_num_threads(before);
    CHECK(one.contribution_max == four.contribution_max);
    CHECK(one.contribution_sum == four.contribution_sum);
}

TEST_CASE("gaussian contributions on stiff scenes", "[render][contributions][stress]") {
    std::mt19937 rng(5);
    const Camera cam = test::reduction_camera(rng, 40, 30);
    SECTION("all Gaussians at one point, opacity 0 and 1, scales 1e-8 and 1e4") {
        GaussianCloud c = test::reduction_scene(64, 2, 9);
        for (std::size_t i = 0; i < c.size(); ++i) {
            for (int j = 0; j < 3; ++j) c.means[3 * i + j] = 0.0f;
            const float s = i % 3 == 0 ? 1e-8f : i % 3 == 1 ? 1e4f : 0.1f;
            for (int j = 0; j < 3; ++j) c.scales[3 * i + j] = s;
            c.opacities[i] = i % 2 ? 1.0f : 0.0f;
        }
        const test::CompositeReference ref = test::composite_reference(c, cam, contribution_options(Precision::Float64));
        const RenderResult r = render(c, cam, contribution_options(Precision::Float64));
        CHECK(max_rel(r.contribution_max, ref.contrib_max, 1e-30) <= 1e-7);
        CHECK(max_rel(r.contribution_sum, ref.contrib_sum, 1e-30) <= 1e-7);
        for (std::size_t i = 0; i < c.size(); i += 2) CHECK(r.contribution_max[i] == 0.0f);  // opacity 0
    }
    SECTION("empty cloud") {
        const RenderResult r = render(GaussianCloud(0, 1), cam, contribution_options(Precision::Float32));
        CHECK(r.has_gaussian_contributions);
        CHECK(r.contribution_max.empty());
        CHECK(r.contribution_sum.empty());
    }
}

TEST_CASE("gaussian contributions are refused by the CUDA back end", "[render][contributions]") {
    RenderOptions o = contribution_options(Precision::Float32);
    o.backend = Backend::Cuda;
    const GaussianCloud c(1, 0);
    CHECK_THROWS_AS(render(c, Camera(10, 10, 5, 5, 10, 10), o), DeviceError);
    CHECK_THROWS_WITH(render(c, Camera(10, 10, 5, 5, 10, 10), o), Catch::Matchers::Contains("gaussian_contributions"));
}
