// reduce_sh (reduce/reduce_sh.h): the band bound against dense sampling of directions (and its
// tightness for zonal bands), the choice of the smallest degree, the rendered-pixel guarantee on
// random clouds of degree 1-3 and random cameras, and that a reduced cloud carries no higher band.
#include "avsplat/reduce/reduce_sh.h"
#include "avsplat/core/sh.h"
#include "avsplat/io/ply.h"
#include "avsplat/render/render.h"
#include "reference/reduction_scenes.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

using namespace avsplat;

namespace {

/// n directions spread evenly over the sphere (Fibonacci lattice).
std::vector<Eigen::Vector3d> sphere_directions(int n) {
    std::vector<Eigen::Vector3d> d;
    const double golden = M_PI * (3.0 - std::sqrt(5.0));
    for (int k = 0; k < n; ++k) {
        const double z = 1.0 - 2.0 * (k + 0.5) / n, r = std::sqrt(1.0 - z * z);
        d.emplace_back(r * std::cos(golden * k), r * std::sin(golden * k), z);
    }
    return d;
}

/// max over the directions of |colour(degree D) - colour(degree d)| over the channels, i.e.
/// of the dropped bands' value, evaluated with the renderer's eval_sh in double.
double sampled_truncation(const float* sh, int from, int to, const std::vector<Eigen::Vector3d>& dirs) {
    double worst = 0.0;
    for (const Eigen::Vector3d& d : dirs) {
        double full[3], cut[3];
        sh::eval_sh(from, sh, d.x(), d.y(), d.z(), full);
        sh::eval_sh(to, sh, d.x(), d.y(), d.z(), cut);
        for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(full[c] - cut[c]));
    }
    return worst;
}

}  // namespace

TEST_CASE("reduce_sh: the band bound holds against dense sampling and is tight for zonal bands", "[reduce_sh]") {
    const std::vector<Eigen::Vector3d> dirs = sphere_directions(20000);
    std::mt19937 rng(1);
    std::normal_distribution<double> g(0.0, 1.0);
    for (int trial = 0; trial < 200; ++trial) {
        float sh[16 * 3];
        for (float& x : sh) x = float(g(rng));
        for (int to = 0; to < 3; ++to) {
            const double bound = sh_truncation_bound(sh, 3, to);
            const double sampled = sampled_truncation(sh, 3, to, dirs);
            CHECK(sampled <= bound * (1.0 + 1e-12));
            CHECK(sampled >= bound / 8.0);  // within sqrt(2l + 1) per band; never absurdly loose
        }
    }
    // A band whose coefficients are Y_lm(a) for a unit axis a (a zonal harmonic about a): the
    // bound is attained at d = a.
    for (int l = 1; l <= 3; ++l) {
        Eigen::Vector3d a(g(rng), g(rng), g(rng));
        a.normalize();
        float sh[16 * 3] = {};
        float basis[16 * 3] = {};
        for (int k = l * l; k < (l + 1) * (l + 1); ++k) {
            // Y_lm(a) is the colour of the unit coefficient vector e_k at direction a.
            std::fill(std::begin(basis), std::end(basis), 0.0f);
            basis[3 * k] = 1.0f;
            double rgb[3];
            sh::eval_sh(3, basis, a.x(), a.y(), a.z(), rgb);
            sh[3 * k] = float(rgb[0]);
        }
        std::vector<Eigen::Vector3d> with_axis = dirs;
        with_axis.push_back(a);
        const double bound = sh_truncation_bound(sh, 3, l - 1);
        CHECK(sampled_truncation(sh, 3, l - 1, with_axis) == Approx(bound).epsilon(1e-6));
    }
}

TEST_CASE("reduce_sh chooses the smallest degree within max_error for every Gaussian", "[reduce_sh]") {
    GaussianCloud c = test::reduction_scene(50, 3, 4, 0.0);  // higher bands all zero ...
    c.sh[(7 * 16 + 5) * 3 + 1] = 0.01f;                       // ... but one band-2 coefficient of Gaussian 7
    const double band2 = std::sqrt(5.0 / (4.0 * M_PI)) * 0.01;
    ReduceShResult r = reduce_sh(c, 0.5 * band2);
    CHECK(r.sh_degree == 2);
    CHECK(r.sh_degree_before == 3);
    CHECK(r.max_error_bound == 0.0);  // band 3 is zero everywhere
    CHECK(r.gaussians_by_degree == std::array<std::size_t, 4>{49, 0, 1, 0});
    CHECK(r.bytes_saved == 50 * (16 - 9) * 3 * 4);
    r = reduce_sh(c, 2.0 * band2);
    CHECK(r.sh_degree == 0);
    CHECK(r.max_error_bound == Approx(band2).epsilon(1e-6));
    CHECK(r.cloud.sh.size() == 50 * 3);
    // Forced degree: the bound is reported, not met.
    r = reduce_sh(c, 0.0, 1);
    CHECK(r.sh_degree == 1);
    CHECK(r.max_error_bound == Approx(band2).epsilon(1e-6));
    CHECK(r.gaussians_by_degree == std::array<std::size_t, 4>{49, 0, 1, 0});
    // Everything but the SH is kept as it was.
    CHECK(r.cloud.means == c.means);
    CHECK(r.cloud.opacities == c.opacities);
    CHECK(!r.cloud.antialiased);
    c.antialiased = true;  // and the antialiasing flag: the same Gaussians, the same filter
    CHECK(reduce_sh(c, 0.0, 1).cloud.antialiased);
    c.antialiased = false;
    for (std::size_t i = 0; i < c.size(); ++i)
        for (int j = 0; j < 4 * 3; ++j) CHECK(r.cloud.sh[i * 12 + j] == c.sh[i * 48 + j]);
    CHECK_THROWS_WITH(reduce_sh(c, -1.0), Catch::Matchers::Contains("max_error"));
    CHECK_THROWS_WITH(reduce_sh(c, 0.1, 4), Catch::Matchers::Contains("degree"));
    CHECK(reduce_sh(GaussianCloud(0, 2)).sh_degree == 0);
}

TEST_CASE("reduce_sh with max_error 1/255 changes no rendered pixel by more than 1/255", "[reduce_sh]") {
    std::mt19937 rng(8);
    int reduced = 0;
    for (std::uint32_t seed = 0; seed < 12; ++seed) {
        const int degree = 1 + int(seed % 3);
        // Higher bands of a size around the bound, so that some clouds reduce and some do not.
        const double band_scale = seed % 2 ? 0.0005 : 0.02;
        const GaussianCloud cloud = test::reduction_scene(300, degree, 500 + seed, band_scale, 0.02, 0.5);
        const ReduceShResult r = reduce_sh(cloud, 1.0 / 255.0);
        CHECK(r.max_error_bound <= 1.0 / 255.0);
        reduced += r.sh_degree < degree;
        for (int k = 0; k < 3; ++k) {
            const Camera cam = test::reduction_camera(rng, 48, 36, 2.0 + k);
            for (const Precision p : {Precision::Float64, Precision::Float32}) {
                RenderOptions o;
                o.precision = p;
                o.background = {0.3f, 0.3f, 0.3f};
                const RenderResult a = render(cloud, cam, o), b = render(r.cloud, cam, o);
                double worst = 0.0;
                for (std::size_t j = 0; j < a.color.size(); ++j)
                    worst = std::max(worst, std::abs(double(a.color[j]) - double(b.color[j])));
                // float32: the two renders round differently (colours up to a few units).
                CHECK(worst <= r.max_error_bound + (p == Precision::Float64 ? 1e-12 : 2e-6));
                CHECK(worst <= 1.0 / 255.0 + (p == Precision::Float64 ? 1e-12 : 2e-6));
            }
        }
    }
    CHECK(reduced >= 3);
}

TEST_CASE("reduce_sh to degree 0: no higher band is stored, rendered or written", "[reduce_sh]") {
    const GaussianCloud cloud = test::reduction_scene(40, 3, 6, 0.001);
    const ReduceShResult r = reduce_sh(cloud, 0.1);
    REQUIRE(r.sh_degree == 0);
    CHECK(r.cloud.sh.size() == cloud.size() * 3);
    const std::string path = std::string(AVSPLAT_TEST_TMP) + "/reduce_sh_degree0.ply";
    write_ply(path, r.cloud);
    const GaussianCloud back = read_ply(path);
    CHECK(back.sh_degree == 0);
    CHECK(back.sh == r.cloud.sh);
    std::remove(path.c_str());
}
