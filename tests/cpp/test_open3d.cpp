#include "avsplat/open3d/conversion.h"
#include "avsplat/core/sh.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <random>

using avsplat::GaussianCloud;
namespace core = open3d::core;

namespace {

GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f), pos(0.05f, 0.95f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = u(rng);
    for (auto& v : c.scales) v = pos(rng);
    for (auto& v : c.rotations) v = u(rng);
    for (auto& v : c.opacities) v = pos(rng);
    for (auto& v : c.sh) v = u(rng);
    return c;
}

}  // namespace

TEST_CASE("to_open3d uses Open3D's Gaussian-splat attribute names and encodings", "[open3d]") {
    GaussianCloud c = random_cloud(5, 2, 1);
    c.confidence = {1, 2, 3, 4, 5};
    c.set_extra("depth_error", {0.1f, 0.2f, 0.3f, 0.4f, 0.5f});
    const auto pcd = avsplat::to_open3d(c);
    CHECK(pcd.GetPointPositions().GetShape() == core::SizeVector{5, 3});
    CHECK(pcd.GetPointAttr("scale").GetShape() == core::SizeVector{5, 3});
    CHECK(pcd.GetPointAttr("rot").GetShape() == core::SizeVector{5, 4});
    CHECK(pcd.GetPointAttr("opacity").GetShape() == core::SizeVector{5, 1});
    CHECK(pcd.GetPointAttr("f_dc").GetShape() == core::SizeVector{5, 3});
    CHECK(pcd.GetPointAttr("f_rest").GetShape() == core::SizeVector{5, 8, 3});
    // Opacity is stored as a logit; f_rest holds coefficients 1.. in [K-1][3] order.
    const float logit = pcd.GetPointAttr("opacity")[3][0].Item<float>();
    CHECK(1.f / (1.f + std::exp(-logit)) == Approx(c.opacities[3]).epsilon(1e-6));
    CHECK(pcd.GetPointAttr("f_rest")[2][4][1].Item<float>() == c.sh[2 * 27 + 5 * 3 + 1]);
    CHECK(pcd.GetPointAttr("f_dc")[4][2].Item<float>() == c.sh[4 * 27 + 2]);
    CHECK(pcd.GetPointAttr("confidence")[1][0].Item<float>() == 2.f);
    CHECK(pcd.GetPointAttr("depth_error")[4][0].Item<float>() == 0.5f);
}

TEST_CASE("from_open3d(to_open3d(c)) returns the cloud", "[open3d]") {
    for (int degree = 0; degree <= 3; ++degree) {
        GaussianCloud c = random_cloud(7, degree, 10 + degree);
        c.set_extra("b", std::vector<float>(7, 2.f));
        c.set_extra("a", std::vector<float>(7, 1.f));
        const GaussianCloud back = avsplat::from_open3d(avsplat::to_open3d(c));
        CHECK(back.sh_degree == degree);
        CHECK(back.means == c.means);
        CHECK(back.scales == c.scales);
        CHECK(back.rotations == c.rotations);
        CHECK(back.sh == c.sh);
        for (std::size_t i = 0; i < c.size(); ++i) CHECK(back.opacities[i] == Approx(c.opacities[i]).epsilon(1e-6));
        // Extra channels come back in name order (Open3D's attribute map is unordered).
        REQUIRE(back.extras.size() == 2);
        CHECK(back.extras[0].name == "a");
        CHECK(back.extras[1].values[0] == 2.f);
        CHECK_FALSE(back.has_confidence());
    }
}

TEST_CASE("from_open3d names the missing or malformed attribute", "[open3d]") {
    auto pcd = avsplat::to_open3d(random_cloud(4, 1, 3));
    auto missing = pcd.Clone();
    missing.RemovePointAttr("rot");
    CHECK_THROWS_WITH(avsplat::from_open3d(missing), Catch::Contains("'rot'"));
    auto bad = pcd.Clone();
    bad.SetPointAttr("scale", core::Tensor::Zeros({4, 2}, core::Float32));
    CHECK_THROWS_WITH(avsplat::from_open3d(bad), Catch::Contains("'scale'"));
    auto bad_rest = pcd.Clone();
    bad_rest.SetPointAttr("f_rest", core::Tensor::Zeros({4, 2, 3}, core::Float32));
    CHECK_THROWS_WITH(avsplat::from_open3d(bad_rest), Catch::Contains("'f_rest'"));
    // Double tensors are converted.
    auto dbl = pcd.Clone();
    dbl.SetPointAttr("scale", pcd.GetPointAttr("scale").To(core::Float64));
    CHECK(avsplat::from_open3d(dbl).scales == avsplat::from_open3d(pcd).scales);
}

TEST_CASE("to_open3d_legacy gives points and SH-DC colours clamped to [0, 1]", "[open3d]") {
    GaussianCloud c(3, 1);
    c.means = {1, 2, 3, 4, 5, 6, 7, 8, 9};
    // Colours 0.25, 0.5 and 2.0 (clamped to 1) in the red channel.
    c.sh[0] = float(avsplat::sh::color_to_dc(0.25));
    c.sh[12] = 0.f;
    c.sh[24] = float(avsplat::sh::color_to_dc(2.0));
    const auto legacy = avsplat::to_open3d_legacy(c);
    REQUIRE(legacy.points_.size() == 3);
    CHECK(legacy.points_[2] == Eigen::Vector3d(7, 8, 9));
    CHECK(legacy.colors_[0][0] == Approx(0.25).epsilon(1e-6));
    CHECK(legacy.colors_[1][0] == Approx(0.5));
    CHECK(legacy.colors_[2][0] == 1.0);
}
