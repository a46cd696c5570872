#include "avsplat/metrics/geometry_metrics.h"
#include "avsplat/point_maps/point_maps.h"
#include "avsplat/core/sh.h"

#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

using avsplat::Camera;
using avsplat::ConfidenceMapping;
using avsplat::GaussianCloud;
using avsplat::PointMapOptions;
using avsplat::PointMaps;

namespace {

std::vector<float> random_points(std::size_t n, unsigned seed, float lo = -1.f, float hi = 1.f) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(lo, hi);
    std::vector<float> p(3 * n);
    for (auto& v : p) v = u(rng);
    return p;
}

double dist2(const float* a, const float* b) {
    double s = 0.0;
    for (int c = 0; c < 3; ++c) s += (double(a[c]) - double(b[c])) * (double(a[c]) - double(b[c]));
    return s;
}

// Brute force: squared distances from point i to all points, ascending (itself included).
std::vector<double> sorted_d2(const std::vector<float>& p, std::size_t i) {
    std::vector<double> d;
    for (std::size_t j = 0; j < p.size() / 3; ++j) d.push_back(dist2(&p[3 * i], &p[3 * j]));
    std::sort(d.begin(), d.end());
    return d;
}

PointMaps plain(const std::vector<float>& points, const std::vector<float>& colors) {
    PointMaps m;
    m.views = 1;
    m.height = 1;
    m.width = static_cast<int>(points.size() / 3);
    m.points = points.data();
    m.colors = colors.data();
    return m;
}

Eigen::Matrix3d rotation_of(const GaussianCloud& g, std::size_t i) {
    const auto q = g.rotation(i);
    return Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
}

// A camera at the origin looking along +z (identity pose), focal f, W x H.
Camera axis_camera(double f, int w, int h) { return Camera(f, f, 0.5 * w, 0.5 * h, w, h); }

}  // namespace

TEST_CASE("kNN scale is the RMS distance to the k nearest other points (brute force)", "[point_maps]") {
    const std::vector<float> p = random_points(400, 1);
    const std::vector<float> colors(p.size(), 0.5f);
    for (int k : {1, 3, 7}) {
        PointMapOptions o;
        o.k = k;
        o.flat = false;
        o.min_scale = 0.0;
        o.scale_multiplier = 1.0;  // the 3DGS initialisation
        const GaussianCloud g = avsplat::gaussians_from_point_maps(plain(p, colors), {}, o);
        REQUIRE(g.size() == 400);
        for (std::size_t i = 0; i < g.size(); ++i) {
            const std::vector<double> d = sorted_d2(p, i);
            double s = 0.0;
            for (int t = 1; t <= k; ++t) s += d[t];  // d[0] = 0 is the point itself
            const double expected = std::sqrt(s / k);
            for (int a = 0; a < 3; ++a) REQUIRE(g.scales[3 * i + a] == Approx(expected).epsilon(1e-5));
            REQUIRE(g.rotations[4 * i] == 1.f);  // isotropic: identity
        }
    }
}

TEST_CASE("kNN scale uses every other point when there are fewer than k", "[point_maps]") {
    const std::vector<float> p = {0, 0, 0, 3, 0, 0, 0, 4, 0};
    const std::vector<float> c(9, 0.5f);
    PointMapOptions o;
    o.k = 5;
    o.flat = false;
    const GaussianCloud g = avsplat::gaussians_from_point_maps(plain(p, c), {}, o);
    // The default scale_multiplier is 0.5.
    CHECK(g.scales[0] == Approx(0.5 * std::sqrt((9.0 + 16.0) / 2.0)));  // two others: 3 and 4
    CHECK(g.scales[3] == Approx(0.5 * std::sqrt((9.0 + 25.0) / 2.0)));  // 3 and 5
}

TEST_CASE("PCA normal of points on a plane is the plane's normal; the Gaussian lies flat", "[point_maps]") {
    const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
    const Eigen::Vector3d t1 = n.unitOrthogonal(), t2 = n.cross(t1);
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<float> p;
    for (int i = 0; i < 300; ++i) {
        const Eigen::Vector3d x = Eigen::Vector3d(0.2, 0.1, -0.4) + u(rng) * t1 + u(rng) * t2;
        for (int c = 0; c < 3; ++c) p.push_back(static_cast<float>(x[c]));
    }
    const std::vector<float> colors(p.size(), 0.5f);
    PointMapOptions o;
    o.thickness = 0.2;
    const GaussianCloud g = avsplat::gaussians_from_point_maps(plain(p, colors), {}, o);
    for (std::size_t i = 0; i < g.size(); ++i) {
        const Eigen::Matrix3d R = rotation_of(g, i);
        REQUIRE(std::abs(R.col(2).dot(n)) == Approx(1.0).margin(1e-5));
        REQUIRE(g.scales[3 * i] == g.scales[3 * i + 1]);
        REQUIRE(g.scales[3 * i + 2] == Approx(0.2 * g.scales[3 * i]).epsilon(1e-6));
    }
}

TEST_CASE("with cameras the scale is the pixel footprint, stretched along the slant", "[point_maps]") {
    // One 5 x 5 view from a camera at the origin looking along +z, f = 10: the centre pixel's
    // ray is the optical axis. The plane through (0, 0, 2) is tilted by 60 degrees about x.
    const double f = 10.0, z0 = 2.0, tilt = 60.0 * M_PI / 180.0;
    const Eigen::Vector3d n(0.0, std::sin(tilt), -std::cos(tilt));
    const Camera cam = axis_camera(f, 5, 5);
    std::vector<float> points, colors(75, 0.5f), normals;
    for (int row = 0; row < 5; ++row)
        for (int col = 0; col < 5; ++col) {
            const Eigen::Vector3d d((col + 0.5 - 2.5) / f, (row + 0.5 - 2.5) / f, 1.0);
            const double t = z0 * n.z() / n.dot(d);  // ray-plane intersection, n . (x - (0,0,z0)) = 0
            const Eigen::Vector3d x = t * d;
            for (int c = 0; c < 3; ++c) {
                points.push_back(static_cast<float>(x[c]));
                normals.push_back(static_cast<float>(-n[c]));  // either sign is accepted
            }
        }
    PointMaps m;
    m.views = 1;
    m.height = 5;
    m.width = 5;
    m.points = points.data();
    m.colors = colors.data();

    SECTION("hand-computed centre pixel, given normals") {
        m.normals = normals.data();
        const GaussianCloud g = avsplat::gaussians_from_point_maps(m, {cam});
        const std::size_t c = 12;  // row 2, col 2; footprint z0 / f = 0.2, default multiplier 0.5
        CHECK(g.scales[3 * c + 0] == Approx(0.2).epsilon(1e-6));  // stretched by 1 / cos 60 = 2
        CHECK(g.scales[3 * c + 1] == Approx(0.1).epsilon(1e-6));
        CHECK(g.scales[3 * c + 2] == Approx(0.01).epsilon(1e-6));
        const Eigen::Matrix3d R = rotation_of(g, c);
        CHECK(R.col(2).dot(n) == Approx(1.0).margin(1e-6));  // faces the camera: n . (0,0,1) < 0
        // The stretched axis is the ray's direction within the plane.
        CHECK(std::abs(R.col(0).dot(Eigen::Vector3d(0.0, std::cos(tilt), std::sin(tilt)))) == Approx(1.0).margin(1e-6));
    }
    SECTION("every pixel against the footprint rule, PCA normals") {
        PointMapOptions o;
        o.scale_multiplier = 1.0;
        const GaussianCloud g = avsplat::gaussians_from_point_maps(m, {cam}, o);
        REQUIRE(g.size() == 25);
        for (std::size_t i = 0; i < 25; ++i) {
            const Eigen::Vector3d x(points[3 * i], points[3 * i + 1], points[3 * i + 2]);
            const double s = x.z() / f;
            const double stretch = std::min(1.0 / std::abs(x.normalized().dot(n)), 4.0);
            CHECK(g.scales[3 * i] == Approx(s * stretch).epsilon(1e-4));
            CHECK(g.scales[3 * i + 1] == Approx(s).epsilon(1e-5));
            CHECK(std::abs(rotation_of(g, i).col(2).dot(n)) == Approx(1.0).margin(1e-4));
        }
    }
    SECTION("the stretch is capped at max_stretch") {
        m.normals = normals.data();
        PointMapOptions o;
        o.max_stretch = 1.5;
        o.scale_multiplier = 1.0;
        const GaussianCloud g = avsplat::gaussians_from_point_maps(m, {cam}, o);
        CHECK(g.scales[3 * 12] == Approx(1.5 * z0 / f).epsilon(1e-6));
        o.scale_multiplier = 2.0;
        const GaussianCloud g2 = avsplat::gaussians_from_point_maps(m, {cam}, o);
        CHECK(g2.scales[3 * 12 + 1] == Approx(2.0 * z0 / f).epsilon(1e-6));
    }
}

TEST_CASE("opacity, colour, confidence channel and pixel order", "[point_maps]") {
    // 2 views of 1 x 2 pixels; pixel 1 of view 0 is invalid.
    const std::vector<float> p = {0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
    const std::vector<float> colors = {0.5f, 0.5f, 0.5f, 0.f, 0.f, 0.f, 1.f, 0.25f, 0.75f, 0.2f, 0.4f, 0.6f};
    const std::vector<float> conf = {0.5f, 0.9f, 0.25f, 2.0f};
    const std::vector<std::uint8_t> valid = {1, 0, 1, 1};
    PointMaps m;
    m.views = 2;
    m.height = 1;
    m.width = 2;
    m.points = p.data();
    m.colors = colors.data();
    m.valid = valid.data();

    SECTION("no confidence: default opacity, no confidence channel") {
        PointMapOptions o;
        o.default_opacity = 0.7;
        const GaussianCloud g = avsplat::gaussians_from_point_maps(m, {}, o);
        REQUIRE(g.size() == 3);
        CHECK_FALSE(g.has_confidence());
        for (float a : g.opacities) CHECK(a == Approx(0.7));
        // Pixel order of the valid pixels: 0, 2, 3.
        CHECK(g.means == std::vector<float>{0, 0, 1, 0, 1, 1, 1, 1, 1});
        const std::size_t source[3] = {0, 2, 3};
        for (std::size_t j = 0; j < 3; ++j)
            for (int c = 0; c < 3; ++c)
                CHECK(avsplat::sh::dc_to_color<double>(g.sh[3 * j + c]) == Approx(colors[3 * source[j] + c]).margin(1e-6));
    }
    SECTION("the three confidence mappings") {
        m.confidence = conf.data();
        PointMapOptions o;
        o.confidence_mapping = ConfidenceMapping::Logit;
        GaussianCloud g = avsplat::gaussians_from_point_maps(m, {}, o);
        CHECK(g.confidence == std::vector<float>{0.5f, 0.25f, 2.0f});
        CHECK(g.opacities[0] == Approx(1.0 / (1.0 + std::exp(-0.5))));
        CHECK(g.opacities[2] == Approx(1.0 / (1.0 + std::exp(-2.0))));
        const std::vector<float> prob = {0.5f, 0.9f, 0.25f, 1.0f};
        m.confidence = prob.data();
        o.confidence_mapping = ConfidenceMapping::Probability;
        g = avsplat::gaussians_from_point_maps(m, {}, o);
        CHECK(g.opacities == std::vector<float>{0.5f, 0.25f, 1.0f});
        m.confidence = conf.data();
        o.confidence_mapping = ConfidenceMapping::Positive;
        g = avsplat::gaussians_from_point_maps(m, {}, o);
        CHECK(g.opacities[1] == Approx(0.25 / 1.25));
        CHECK(g.opacities[2] == Approx(2.0 / 3.0));
    }
}

TEST_CASE("gaussians_from_point_maps rejects bad input, naming the field and pixel", "[point_maps]") {
    std::vector<float> p = {0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
    const std::vector<float> colors(12, 0.5f);
    PointMaps m;
    m.views = 2;
    m.height = 1;
    m.width = 2;
    m.points = p.data();
    m.colors = colors.data();
    const Camera cam = axis_camera(1.0, 2, 1);

    p[7] = NAN;  // pixel 2: view 1, row 0, col 0
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m),
                      Catch::Contains("points[2] (view 1, row 0, col 0) is not finite"));
    const std::vector<std::uint8_t> valid = {1, 1, 0, 1};
    m.valid = valid.data();
    CHECK(avsplat::gaussians_from_point_maps(m).size() == 3);  // the NaN pixel is invalid
    m.valid = nullptr;
    p[7] = 0.f;

    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m, {cam}), Catch::Contains("cameras has 1 entries for 2 views"));
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m, {axis_camera(1.0, 3, 1), cam}),
                      Catch::Contains("cameras[0] is 3 x 1"));
    p[11] = -1.f;  // pixel 3 behind its camera
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m, {cam, cam}),
                      Catch::Contains("points[3] (view 1, row 0, col 1) is at or behind its camera"));
    p[11] = 1.f;

    const std::vector<float> conf = {0.5f, 1.5f, 0.5f, 0.5f};
    m.confidence = conf.data();
    PointMapOptions o;
    o.confidence_mapping = ConfidenceMapping::Probability;
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m, {}, o), Catch::Contains("confidence[1]"));
    m.confidence = nullptr;

    const std::vector<float> zero(12, 0.f);
    m.normals = zero.data();
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m), Catch::Contains("normals[0] (view 0, row 0, col 0) is zero"));
    m.normals = nullptr;

    o = PointMapOptions();
    o.k = 0;
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m, {}, o), Catch::Contains("options.k"));
    o = PointMapOptions();
    o.thickness = 0.0;
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m, {}, o), Catch::Contains("options.thickness"));

    m.views = 1;
    m.width = 1;
    CHECK_THROWS_WITH(avsplat::gaussians_from_point_maps(m), Catch::Contains("at least 2 valid points"));
    m.views = 0;
    CHECK(avsplat::gaussians_from_point_maps(m).empty());
}

TEST_CASE("duplicated points get the minimum scale, never zero", "[point_maps]") {
    const std::vector<float> p = {1, 2, 3, 1, 2, 3, 1, 2, 3};
    const std::vector<float> c(9, 0.5f);
    PointMapOptions o;
    o.min_scale = 1e-4;
    const GaussianCloud g = avsplat::gaussians_from_point_maps(plain(p, c), {}, o);
    for (float s : g.scales) CHECK(s == Approx(1e-4));
    CHECK_NOTHROW(avsplat::validate(g));
}

TEST_CASE("point-map results do not depend on the thread count", "[point_maps]") {
    const std::vector<float> p = random_points(3000, 5);
    const std::vector<float> c(p.size(), 0.3f);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const GaussianCloud a = avsplat::gaussians_from_point_maps(plain(p, c));
    const auto kept_a = avsplat::remove_statistical_outliers(p.data(), 3000, 10, 1.0);
    omp_set_num_threads(4);
    const GaussianCloud b = avsplat::gaussians_from_point_maps(plain(p, c));
    const auto kept_b = avsplat::remove_statistical_outliers(p.data(), 3000, 10, 1.0);
    omp_set_num_threads(threads);
    CHECK(a.scales == b.scales);
    CHECK(a.rotations == b.rotations);
    CHECK(kept_a == kept_b);
}

TEST_CASE("statistical outlier removal follows Open3D's rule (brute force)", "[point_maps]") {
    std::vector<float> p = random_points(500, 7);
    const std::vector<float> far = random_points(25, 8, 3.f, 6.f);
    p.insert(p.end(), far.begin(), far.end());
    const std::size_t n = p.size() / 3;
    for (int nb : {1, 5, 20}) {
        for (double ratio : {0.5, 2.0}) {
            std::vector<double> avg(n);
            for (std::size_t i = 0; i < n; ++i) {
                const std::vector<double> d = sorted_d2(p, i);
                double s = 0.0;
                for (int t = 0; t < nb; ++t) s += std::sqrt(d[t]);  // the point itself included
                avg[i] = s / nb;
            }
            const double mu = std::accumulate(avg.begin(), avg.end(), 0.0) / n;
            double ss = 0.0;
            for (double a : avg) ss += (a - mu) * (a - mu);
            const double thr = mu + ratio * std::sqrt(ss / (n - 1));
            std::vector<std::size_t> expected;
            for (std::size_t i = 0; i < n; ++i)
                if (avg[i] <= thr) expected.push_back(i);
            const auto kept = avsplat::remove_statistical_outliers(p.data(), n, nb, ratio);
            CHECK(kept == expected);
            if (nb == 20) {  // the far points are removed
                CHECK(std::none_of(kept.begin(), kept.end(), [](std::size_t i) { return i >= 500; }));
            }
        }
    }
}

TEST_CASE("statistical outlier removal keeps a regular grid and rejects bad input", "[point_maps]") {
    std::vector<float> grid;
    for (int i = 0; i < 10; ++i)
        for (int j = 0; j < 10; ++j) grid.insert(grid.end(), {float(i), float(j), 0.f});
    // nb_neighbors = 1: every mean distance is 0 (the point itself), the threshold is 0 and every
    // point is kept (Open3D's strict "<" would drop them all).
    CHECK(avsplat::remove_statistical_outliers(grid.data(), 100, 1, 2.0).size() == 100);
    CHECK(avsplat::remove_statistical_outliers(grid.data(), 1, 5, 2.0) == std::vector<std::size_t>{0});
    CHECK(avsplat::remove_statistical_outliers(grid.data(), 0, 5, 2.0).empty());
    CHECK_THROWS_WITH(avsplat::remove_statistical_outliers(grid.data(), 100, 0, 2.0), Catch::Contains("nb_neighbors"));
    CHECK_THROWS_WITH(avsplat::remove_statistical_outliers(grid.data(), 100, 5, -1.0), Catch::Contains("std_ratio"));
    grid[3 * 42 + 1] = INFINITY;
    CHECK_THROWS_WITH(avsplat::remove_statistical_outliers(grid.data(), 100, 5, 2.0), Catch::Contains("points[42]"));
}

TEST_CASE("point-set distances match brute force", "[point_maps]") {
    const std::vector<float> a = random_points(300, 11), b = random_points(200, 12, -0.5f, 1.5f);
    auto nearest = [](const std::vector<float>& from, const std::vector<float>& to) {
        std::vector<double> d(from.size() / 3);
        for (std::size_t i = 0; i < d.size(); ++i) {
            double best = INFINITY;
            for (std::size_t j = 0; j < to.size() / 3; ++j) best = std::min(best, dist2(&from[3 * i], &to[3 * j]));
            d[i] = std::sqrt(best);
        }
        return d;
    };
    const std::vector<double> ab = nearest(a, b), ba = nearest(b, a);
    const std::vector<double> got = avsplat::compute_point_cloud_distance(a.data(), 300, b.data(), 200);
    REQUIRE(got.size() == 300);
    for (std::size_t i = 0; i < 300; ++i) REQUIRE(got[i] == Approx(ab[i]).epsilon(1e-6));

    const double mean_ab = std::accumulate(ab.begin(), ab.end(), 0.0) / ab.size();
    const double mean_ba = std::accumulate(ba.begin(), ba.end(), 0.0) / ba.size();
    const double thr = 0.1;
    const double P = std::count_if(ab.begin(), ab.end(), [&](double d) { return d < thr; }) / 300.0;
    const double R = std::count_if(ba.begin(), ba.end(), [&](double d) { return d < thr; }) / 200.0;
    const auto r = avsplat::accuracy_completeness(a.data(), 300, b.data(), 200, thr);
    CHECK(r.accuracy == Approx(mean_ab).epsilon(1e-9));
    CHECK(r.completeness == Approx(mean_ba).epsilon(1e-9));
    CHECK(r.chamfer == Approx(0.5 * (mean_ab + mean_ba)).epsilon(1e-9));
    CHECK(r.precision == Approx(P));
    CHECK(r.recall == Approx(R));
    CHECK(r.fscore == Approx(2 * P * R / (P + R)));
    CHECK(r.threshold == thr);
    CHECK(avsplat::chamfer_distance(a.data(), 300, b.data(), 200) == Approx(r.chamfer).epsilon(1e-12));
}

TEST_CASE("point-set distances: a hand-computed case, order independence and errors", "[point_maps]") {
    const std::vector<float> a = {0, 0, 0, 1, 0, 0}, b = {0, 0, 1};
    const auto r = avsplat::accuracy_completeness(a.data(), 2, b.data(), 1, 1.2);
    CHECK(r.accuracy == Approx((1.0 + std::sqrt(2.0)) / 2.0));
    CHECK(r.completeness == Approx(1.0));
    CHECK(r.chamfer == Approx(0.5 * ((1.0 + std::sqrt(2.0)) / 2.0 + 1.0)));
    CHECK(r.precision == 0.5);
    CHECK(r.recall == 1.0);
    CHECK(r.fscore == Approx(2.0 / 3.0));
    // "Closer than" is strict: at a threshold of exactly 1 nothing counts.
    CHECK(avsplat::accuracy_completeness(a.data(), 2, b.data(), 1, 1.0).fscore == 0.0);

    std::vector<float> p = random_points(100, 13), q = random_points(80, 14);
    const double before = avsplat::chamfer_distance(p.data(), 100, q.data(), 80);
    std::vector<std::size_t> perm(100);
    std::iota(perm.begin(), perm.end(), 0);
    std::shuffle(perm.begin(), perm.end(), std::mt19937(15));
    std::vector<float> shuffled(300);
    for (std::size_t i = 0; i < 100; ++i) std::copy_n(&p[3 * perm[i]], 3, &shuffled[3 * i]);
    CHECK(avsplat::chamfer_distance(shuffled.data(), 100, q.data(), 80) == Approx(before).epsilon(1e-12));

    CHECK_THROWS_WITH(avsplat::chamfer_distance(p.data(), 0, q.data(), 80), Catch::Contains("empty"));
    CHECK_THROWS_WITH(avsplat::accuracy_completeness(p.data(), 100, q.data(), 80, 0.0), Catch::Contains("threshold"));
    CHECK_THROWS_WITH(avsplat::compute_point_cloud_distance(p.data(), 100, q.data(), 0), Catch::Contains("target is empty"));
    CHECK(avsplat::compute_point_cloud_distance(p.data(), 0, q.data(), 0).empty());
    q[3 * 7 + 2] = NAN;
    CHECK_THROWS_WITH(avsplat::accuracy_completeness(p.data(), 100, q.data(), 80, 0.1), Catch::Contains("gt[7]"));
}
