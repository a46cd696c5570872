#include "avsplat/core/framing.h"

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <cmath>
#include <random>

using avsplat::Camera;
using avsplat::FramingOptions;
using avsplat::GaussianCloud;

namespace {

// A box of points [-1, 3] x [0, 1] x [2, 4] sampled uniformly, plus `floaters` points far away.
GaussianCloud box_scene(std::size_t n, std::size_t floaters) {
    GaussianCloud cloud(n + floaters, 0);
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (std::size_t i = 0; i < n; ++i) {
        cloud.means[3 * i + 0] = -1.0f + 4.0f * u(rng);
        cloud.means[3 * i + 1] = u(rng);
        cloud.means[3 * i + 2] = 2.0f + 2.0f * u(rng);
    }
    for (std::size_t i = n; i < n + floaters; ++i) {
        cloud.means[3 * i + 0] = 500.0f;
        cloud.means[3 * i + 1] = -300.0f;
        cloud.means[3 * i + 2] = 800.0f;
    }
    return cloud;
}

Eigen::Vector3d project(const Camera& c, const Eigen::Vector3d& p) {
    const Eigen::Vector4d q = c.world_to_camera * p.homogeneous();
    return {c.fx * q.x() / q.z() + c.cx, c.fy * q.y() / q.z() + c.cy, q.z()};
}

void check_box_in_view(const Camera& c, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
    for (int k = 0; k < 8; ++k) {
        const Eigen::Vector3d corner((k & 1) ? hi.x() : lo.x(), (k & 2) ? hi.y() : lo.y(), (k & 4) ? hi.z() : lo.z());
        const Eigen::Vector3d uvz = project(c, corner);
        INFO("corner " << k << " projects to " << uvz.transpose());
        CHECK(uvz.z() > c.near);
        CHECK(uvz.x() >= 0.0);
        CHECK(uvz.x() <= c.width);
        CHECK(uvz.y() >= 0.0);
        CHECK(uvz.y() <= c.height);
    }
}

}  // namespace

TEST_CASE("robust_bounds are per-axis percentiles, interpolated like numpy", "[framing]") {
    GaussianCloud cloud(5, 0);
    const float xs[5] = {4, 0, 3, 1, 2};
    for (int i = 0; i < 5; ++i) cloud.means[3 * i] = xs[i];
    const auto [lo, hi] = avsplat::robust_bounds(cloud, 10.0, 90.0);
    CHECK(lo.x() == Approx(0.4));  // numpy.percentile([0, 1, 2, 3, 4], 10) = 0.4
    CHECK(hi.x() == Approx(3.6));
    CHECK(lo.y() == 0.0);
    CHECK(hi.y() == 0.0);
    const auto [mn, mx] = avsplat::robust_bounds(cloud, 0.0, 100.0);
    CHECK(mn.x() == 0.0);
    CHECK(mx.x() == 4.0);
    CHECK_THROWS_AS(avsplat::robust_bounds(GaussianCloud(), 2, 98), std::invalid_argument);
    CHECK_THROWS_AS(avsplat::robust_bounds(cloud, 60, 40), std::invalid_argument);
}

TEST_CASE("default_camera keeps the robust bounds in view and ignores a far floater", "[framing]") {
    const GaussianCloud clean = box_scene(2000, 0);
    const GaussianCloud floaty = box_scene(2000, 10);  // 0.5% of the points, 800 units away
    const auto [lo, hi] = avsplat::robust_bounds(floaty);
    const Camera c = avsplat::default_camera(floaty);
    CHECK_NOTHROW(c.validate());
    check_box_in_view(c, lo, hi);
    // The floater does not move the camera: same view as without it, within the sampling noise.
    const Camera c0 = avsplat::default_camera(clean);
    CHECK((c.position() - c0.position()).norm() < 0.2);
    CHECK(c.position().norm() < 20.0);
    // Up is -y: a point above the box centre (smaller y) is higher in the image (smaller v).
    const Eigen::Vector3d centre = 0.5 * (lo + hi);
    CHECK(project(c, centre).y() == Approx(c.cy));
    CHECK(project(c, centre - Eigen::Vector3d(0, 0.5, 0)).y() < c.cy);
    // Positive elevation: the camera is above the target.
    CHECK(c.position().y() < centre.y());
}

TEST_CASE("default_camera fits the box at any aspect ratio and field of view", "[framing]") {
    const GaussianCloud cloud = box_scene(500, 0);
    const auto [lo, hi] = avsplat::robust_bounds(cloud);
    for (const auto& [w, h, fov] : {std::tuple{1600, 400, 30.0}, std::tuple{300, 900, 80.0}, std::tuple{64, 64, 10.0}}) {
        FramingOptions o;
        o.width = w;
        o.height = h;
        o.fov_y_degrees = fov;
        o.up = Eigen::Vector3d(0, 0, 1);  // a z-up scene
        check_box_in_view(avsplat::default_camera(cloud, o), lo, hi);
    }
}

TEST_CASE("orbit_cameras circle the target at one distance and elevation", "[framing]") {
    const GaussianCloud cloud = box_scene(500, 0);
    FramingOptions o;
    o.elevation_degrees = 30.0;
    o.radius = 10.0;
    o.target = Eigen::Vector3d(1, 0.5, 3);
    const auto cams = avsplat::orbit_cameras(cloud, 4, o);
    REQUIRE(cams.size() == 4);
    CHECK(cams[0].name == "orbit_000");
    CHECK(cams[3].name == "orbit_003");
    const Eigen::Vector3d t = *o.target;
    // Hand-computed: azimuth 0 looks along +z from 30 degrees above (up = -y), at distance 10.
    const double c30 = std::cos(M_PI / 6), s30 = 0.5;
    CHECK((cams[0].position() - (t + Eigen::Vector3d(0, -10 * s30, -10 * c30))).norm() < 1e-9);
    // A quarter turn about -y (counter-clockwise seen from above) takes +z to -x.
    CHECK((cams[1].position() - (t + Eigen::Vector3d(10 * c30, -10 * s30, 0))).norm() < 1e-9);
    CHECK((cams[2].position() - (t + Eigen::Vector3d(0, -10 * s30, 10 * c30))).norm() < 1e-9);
    for (const Camera& c : cams) {
        CHECK(project(c, t).x() == Approx(c.cx));
        CHECK(project(c, t).y() == Approx(c.cy));
    }
    // The first orbit camera is the default camera.
    CHECK((cams[0].world_to_camera - avsplat::default_camera(cloud, o).world_to_camera).norm() < 1e-12);
    CHECK_THROWS_AS(avsplat::orbit_cameras(cloud, 0, o), std::invalid_argument);
    o.elevation_degrees = 90.0;
    CHECK_THROWS_WITH(avsplat::orbit_cameras(cloud, 2, o), Catch::Contains("elevation_degrees"));
}
