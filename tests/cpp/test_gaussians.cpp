#include "avsplat/core/gaussians.h"

#include <catch2/catch.hpp>

#include <Eigen/Geometry>
#include <omp.h>

#include <cmath>
#include <limits>
#include <random>

using avsplat::GaussianCloud;

namespace {

GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed, bool confidence = false) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f), pos(0.01f, 1.f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = u(rng);
    for (auto& v : c.scales) v = pos(rng);
    for (auto& v : c.rotations) v = u(rng);
    for (auto& v : c.opacities) v = pos(rng);
    for (auto& v : c.sh) v = u(rng);
    if (confidence) {
        c.confidence.resize(n);
        for (auto& v : c.confidence) v = u(rng);
    }
    return c;
}

}  // namespace

TEST_CASE("sh degree and coefficient count correspond", "[gaussians]") {
    CHECK(avsplat::sh_coeffs_for_degree(0) == 1);
    CHECK(avsplat::sh_coeffs_for_degree(3) == 16);
    CHECK(avsplat::sh_degree_for_coeffs(9) == 2);
    CHECK(avsplat::sh_degree_for_coeffs(5) == -1);
    CHECK_THROWS_AS(GaussianCloud(3, 4), std::invalid_argument);
}

TEST_CASE("from_arrays copies every field in the documented layout", "[gaussians]") {
    const float means[] = {1, 2, 3, 4, 5, 6};
    const float scales[] = {.1f, .2f, .3f, .4f, .5f, .6f};
    const float rot[] = {1, 0, 0, 0, 0, 1, 0, 0};
    const float op[] = {.25f, .75f};
    float sh[2 * 4 * 3];
    for (int k = 0; k < 24; ++k) sh[k] = float(k);
    const float conf[] = {-1.f, 2.f};
    const GaussianCloud c = GaussianCloud::from_arrays(2, 1, means, scales, rot, op, sh, conf);
    REQUIRE(c.size() == 2);
    CHECK(c.sh_coeffs() == 4);
    CHECK(c.mean(1) == Eigen::Vector3f(4, 5, 6));
    CHECK(c.scale(0) == Eigen::Vector3f(.1f, .2f, .3f));
    CHECK(c.rotation(1) == Eigen::Vector4f(0, 1, 0, 0));
    CHECK(c.sh[12 + 5] == 17.f);
    CHECK(c.confidence[1] == 2.f);
    CHECK_NOTHROW(avsplat::validate(c));
}

TEST_CASE("covariance is R S S^T R^T for a hand-computed rotation", "[gaussians]") {
    GaussianCloud c(1, 0);
    // 90 degrees about z, unnormalised on purpose: (w, x, y, z) = 2 * (cos 45, 0, 0, sin 45).
    const float h = 2.f * std::sqrt(0.5f);
    c.rotations = {h, 0, 0, h};
    c.scales = {3, 1, 2};
    const Eigen::Matrix3d cov = c.covariance(0);
    // The x axis (length 3) maps to y, y (length 1) to -x: diag(1, 9, 4).
    CHECK(cov(0, 0) == Approx(1.0).margin(1e-6));
    CHECK(cov(1, 1) == Approx(9.0).margin(1e-6));
    CHECK(cov(2, 2) == Approx(4.0).margin(1e-6));
    CHECK(std::abs(cov(0, 1)) < 1e-6);

    // Random case against an independent Eigen AngleAxis construction.
    const Eigen::AngleAxisd aa(0.7, Eigen::Vector3d(1, 2, 3).normalized());
    const Eigen::Quaterniond q(aa);
    c.rotations = {float(q.w()), float(q.x()), float(q.y()), float(q.z())};
    const Eigen::Matrix3d R = q.toRotationMatrix();
    const Eigen::Matrix3d ref = R * Eigen::Vector3d(9, 1, 4).asDiagonal() * R.transpose();
    CHECK((c.covariance(0) - ref).cwiseAbs().maxCoeff() < 1e-5);
    CHECK_THROWS_AS(c.covariance(1), std::out_of_range);
}

TEST_CASE("bounding box of the means", "[gaussians]") {
    GaussianCloud c(3, 0);
    c.means = {0, 5, -1, 2, -3, 4, 1, 1, 1};
    const auto [lo, hi] = c.bounding_box();
    CHECK(lo == Eigen::Vector3f(0, -3, -1));
    CHECK(hi == Eigen::Vector3f(2, 5, 4));
    CHECK_THROWS_AS(GaussianCloud().bounding_box(), std::invalid_argument);
}

TEST_CASE("validate names the field and the first bad index", "[gaussians]") {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const float inf = std::numeric_limits<float>::infinity();
    auto expect = [](GaussianCloud c, const std::string& text) {
        CHECK_THROWS_WITH(avsplat::validate(c), Catch::Contains(text));
    };
    GaussianCloud base = random_cloud(10, 2, 1, true);
    REQUIRE_NOTHROW(avsplat::validate(base));

    GaussianCloud c = base; c.means[3 * 4 + 1] = nan; c.means[3 * 7] = nan;
    expect(c, "GaussianCloud.means[4]: NaN or Inf");
    c = base; c.sh[5 * 27 + 3] = inf;
    expect(c, "GaussianCloud.sh[5]");
    c = base; c.scales[3 * 2 + 2] = -1e-9f;
    expect(c, "GaussianCloud.scales[2]: negative scale");
    c = base; std::fill_n(&c.rotations[4 * 6], 4, 0.f);
    expect(c, "GaussianCloud.rotations[6]: zero-norm quaternion");
    c = base; c.opacities[9] = 1.0001f;
    expect(c, "GaussianCloud.opacities[9]: opacity outside [0, 1]");
    c = base; c.confidence[3] = -inf;
    expect(c, "GaussianCloud.confidence[3]");
    c = base; c.extras.push_back({"foo", std::vector<float>(10, 0.5f)}); c.extras[0].values[8] = nan;
    expect(c, "GaussianCloud.extras[8]");
    // The boundaries of the ranges pass: scale -0, opacity exactly 0 and 1, one non-zero
    // quaternion component, the largest finite floats.
    c = base; c.scales[0] = -0.f; c.opacities[1] = 0.f; c.opacities[2] = 1.f;
    c.rotations[4 * 3] = c.rotations[4 * 3 + 1] = c.rotations[4 * 3 + 2] = 0.f; c.rotations[4 * 3 + 3] = -1e-30f;
    c.means[5] = std::numeric_limits<float>::max(); c.sh[7] = -std::numeric_limits<float>::max();
    REQUIRE_NOTHROW(avsplat::validate(c));
    c = base; c.scales.pop_back();
    expect(c, "GaussianCloud.scales: expected 30 floats");
    c = base; c.sh.resize(10 * 4 * 3);
    expect(c, "GaussianCloud.sh: expected 270 floats");
    c = base; c.sh_degree = 5;
    expect(c, "sh_degree");
    c = base; c.extras.push_back({"foo", std::vector<float>(9)});
    expect(c, "extras['foo']");
    c = base; c.confidence.resize(4);
    expect(c, "GaussianCloud.confidence: expected 10");
}

TEST_CASE("validate reports the first bad index of a large cloud for any thread count", "[gaussians]") {
    // Above the parallel threshold (common/parallel.h: 2^14): the parallel scan must name the
    // index and field a serial scan names, whichever thread's range holds which defect.
    const std::size_t n = 100000;
    GaussianCloud base = random_cloud(n, 1, 3, true);
    REQUIRE_NOTHROW(avsplat::validate(base));
    const int saved = omp_get_max_threads();
    for (int threads : {1, 2, 3, 4}) {
        omp_set_num_threads(threads);
        GaussianCloud c = base;
        c.opacities[90001] = 2.f;                           // last thread's range
        c.scales[3 * 60007 + 1] = -1.f;                     // a middle range
        c.sh[std::size_t(c.sh_coeffs()) * 3 * 60007] = std::numeric_limits<float>::quiet_NaN();  // same Gaussian, earlier field
        CHECK_THROWS_WITH(avsplat::validate(c), Catch::Contains("GaussianCloud.sh[60007]"));
        c.rotations[4 * 123] = c.rotations[4 * 123 + 1] = c.rotations[4 * 123 + 2] = c.rotations[4 * 123 + 3] = 0.f;
        CHECK_THROWS_WITH(avsplat::validate(c), Catch::Contains("GaussianCloud.rotations[123]: zero-norm quaternion"));
        c = base;
        c.means[3 * (n - 1)] = std::numeric_limits<float>::infinity();  // only the very last one
        CHECK_THROWS_WITH(avsplat::validate(c), Catch::Contains("GaussianCloud.means[99999]"));
    }
    omp_set_num_threads(saved);
}

TEST_CASE("sanitize drops invalid Gaussians, counts each under its first reason, keeps order", "[gaussians]") {
    GaussianCloud c = random_cloud(8, 1, 7, true);
    c.set_extra("label", {0, 1, 2, 3, 4, 5, 6, 7});
    const GaussianCloud original = c;
    c.means[3 * 1] = std::numeric_limits<float>::quiet_NaN();
    c.scales[3 * 1] = -1.f;           // same Gaussian: counted once, as non_finite
    c.scales[3 * 3 + 1] = -2.f;
    std::fill_n(&c.rotations[4 * 5], 4, 0.f);
    c.opacities[6] = -0.5f;
    const avsplat::SanitizeReport rep = avsplat::sanitize(c);
    CHECK(rep.kept == 4);
    CHECK(rep.dropped == 4);
    CHECK(rep.non_finite == 1);
    CHECK(rep.negative_scale == 1);
    CHECK(rep.zero_rotation == 1);
    CHECK(rep.opacity_range == 1);
    CHECK(rep.summary() == "kept 4, dropped 4 (non_finite 1, negative_scale 1, zero_rotation 1, opacity_range 1)");
    REQUIRE(c.size() == 4);
    CHECK(c.find_extra("label")->values == std::vector<float>{0, 2, 4, 7});
    for (std::size_t j = 0; j < 4; ++j) {
        const std::size_t i = std::vector<std::size_t>{0, 2, 4, 7}[j];
        CHECK(c.mean(j) == original.mean(i));
        CHECK(c.confidence[j] == original.confidence[i]);
        CHECK(std::equal(&c.sh[j * 12], &c.sh[j * 12 + 12], &original.sh[i * 12]));
    }
    CHECK_NOTHROW(avsplat::validate(c));
}

TEST_CASE("select and select_mask gather every field", "[gaussians]") {
    GaussianCloud c = random_cloud(6, 3, 3, true);
    c.set_extra("e", {10, 11, 12, 13, 14, 15});
    const GaussianCloud s = avsplat::select(c, {5, 0, 5});
    REQUIRE(s.size() == 3);
    CHECK(s.sh_degree == 3);
    CHECK(s.mean(0) == c.mean(5));
    CHECK(s.rotation(1) == c.rotation(0));
    CHECK(s.find_extra("e")->values == std::vector<float>{15, 10, 15});
    CHECK(std::equal(&s.sh[48], &s.sh[96], &c.sh[0]));
    CHECK_THROWS_WITH(avsplat::select(c, {0, 6}), Catch::Contains("indices[1] = 6"));

    const GaussianCloud m = avsplat::select_mask(c, {0, 1, 0, 0, 1, 0});
    REQUIRE(m.size() == 2);
    CHECK(m.confidence == std::vector<float>{c.confidence[1], c.confidence[4]});
    CHECK_THROWS_AS(avsplat::select_mask(c, {1, 0}), std::invalid_argument);
}

TEST_CASE("concatenate pads lower SH degrees with zeros and checks channels", "[gaussians]") {
    const GaussianCloud a = random_cloud(2, 0, 1);
    const GaussianCloud b = random_cloud(3, 2, 2);
    const GaussianCloud c = avsplat::concatenate({a, b});
    REQUIRE(c.size() == 5);
    CHECK(c.sh_degree == 2);
    CHECK(c.sh.size() == 5u * 9 * 3);
    CHECK(c.sh[0] == a.sh[0]);
    CHECK(c.sh[27 + 2] == a.sh[5]);
    for (int k = 3; k < 27; ++k) CHECK(c.sh[k] == 0.f);
    CHECK(std::equal(&c.sh[54], &c.sh[135], b.sh.begin()));
    CHECK(c.mean(4) == b.mean(2));

    const GaussianCloud with_conf = random_cloud(2, 0, 4, true);
    CHECK_THROWS_WITH(avsplat::concatenate({a, with_conf}), Catch::Contains("clouds[1]"));
    CHECK(avsplat::concatenate({}).size() == 0);
}

TEST_CASE("set_extra checks the length and replaces by name", "[gaussians]") {
    GaussianCloud c(2, 0);
    c.set_extra("x", {1, 2});
    c.set_extra("x", {3, 4});
    REQUIRE(c.extras.size() == 1);
    CHECK(c.extras[0].values == std::vector<float>{3, 4});
    CHECK_THROWS_WITH(c.set_extra("y", {1}), Catch::Contains("expected 2 values"));
    CHECK(c.find_extra("nope") == nullptr);
}
