// simplify (reduce/simplify.h): the pairwise moment match against its closed form written here,
// budgets, determinism, the stiff cases and a merge round against the brute-force round. The merge
// cost and its bound: test_merge_cost.cpp; the neighbour search: test_all_knn.cpp.
#include "avsplat/reduce/simplify.h"

#include "reduce/moment_merge.h"
#include "reduce/simplify_methods.h"
#include "simplify_clouds.h"

#include <catch2/catch.hpp>
#include <Eigen/Geometry>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <stdexcept>
#include <tuple>
#include <vector>

using avsplat::GaussianCloud;
using avsplat::SimplifyMethod;
using avsplat::SimplifyOptions;

using simplify_test::area_ref;
using simplify_test::clustered;
using simplify_test::kPi;

namespace {

Eigen::Matrix3d covariance_of(const GaussianCloud& c, std::size_t i) {
    const Eigen::Quaterniond q(c.rotations[4 * i], c.rotations[4 * i + 1], c.rotations[4 * i + 2], c.rotations[4 * i + 3]);
    const Eigen::Matrix3d r = q.normalized().toRotationMatrix();
    const Eigen::Vector3d s(c.scales[3 * i], c.scales[3 * i + 1], c.scales[3 * i + 2]);
    return r * s.cwiseProduct(s).asDiagonal() * r.transpose();
}

SimplifyOptions count(std::size_t n, SimplifyMethod m) {
    SimplifyOptions o;
    o.target_count = n;
    o.method = m;
    return o;
}

bool same(const GaussianCloud& a, const GaussianCloud& b) {
    return a.means == b.means && a.scales == b.scales && a.rotations == b.rotations && a.opacities == b.opacities &&
           a.sh == b.sh && a.confidence == b.confidence && a.sh_degree == b.sh_degree;
}

}  // namespace
TEST_CASE("simplify: two Gaussians merge by moment matching as the closed form", "[simplify]") {
    GaussianCloud c(2, 1);
    const float m0[3] = {0.3f, -0.2f, 1.0f}, m1[3] = {0.9f, 0.4f, 0.7f};
    const float s0[3] = {0.2f, 0.05f, 0.1f}, s1[3] = {0.4f, 0.3f, 0.02f};
    const float q0[4] = {0.9f, 0.1f, -0.3f, 0.2f}, q1[4] = {0.2f, 0.7f, 0.1f, -0.4f};
    for (int a = 0; a < 3; ++a) c.means[a] = m0[a], c.means[3 + a] = m1[a], c.scales[a] = s0[a], c.scales[3 + a] = s1[a];
    for (int a = 0; a < 4; ++a) c.rotations[a] = q0[a], c.rotations[4 + a] = q1[a];
    c.opacities = {0.8f, 0.3f};
    for (int k = 0; k < 12; ++k) c.sh[k] = 0.1f * float(k), c.sh[12 + k] = -0.05f * float(k);

    // Closed form: weights by opacity x surface area; mean and covariance by the law of total
    // variance; opacity = ink over the merged area, capped at 1.
    const double w0 = 0.8 * area_ref(s0[0], s0[1], s0[2]), w1 = 0.3 * area_ref(s1[0], s1[1], s1[2]);
    const double p0 = w0 / (w0 + w1), p1 = w1 / (w0 + w1);
    const Eigen::Vector3d mu0(m0[0], m0[1], m0[2]), mu1(m1[0], m1[1], m1[2]);
    const Eigen::Vector3d mu = p0 * mu0 + p1 * mu1;
    const Eigen::Matrix3d sigma = p0 * (covariance_of(c, 0) + (mu0 - mu) * (mu0 - mu).transpose()) +
                                  p1 * (covariance_of(c, 1) + (mu1 - mu) * (mu1 - mu).transpose());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sigma);
    const Eigen::Vector3d ax = eig.eigenvalues().cwiseSqrt();
    const double opacity = std::min((w0 + w1) / area_ref(ax[0], ax[1], ax[2]), 1.0);

    for (SimplifyMethod method : {SimplifyMethod::Merge}) {
        const auto r = avsplat::simplify(c, count(1, method));
        REQUIRE(r.output_count == 1);
        const GaussianCloud& g = r.cloud;
        for (int a = 0; a < 3; ++a) CHECK(g.means[a] == Approx(mu[a]).epsilon(1e-6));
        const Eigen::Matrix3d got = covariance_of(g, 0);
        CHECK((got - sigma).norm() <= 1e-5 * sigma.norm());
        for (int a = 0; a < 3; ++a) CHECK(g.scales[a] == Approx(ax[a]).epsilon(1e-5));  // increasing
        CHECK(g.rotations[0] >= 0.f);
        CHECK(g.opacities[0] == Approx(opacity).epsilon(1e-6));
        for (int k = 0; k < 12; ++k)
            CHECK(g.sh[k] == Approx(p0 * c.sh[k] + p1 * c.sh[12 + k]).margin(1e-7).epsilon(1e-6));
        CHECK(r.iterations == 1);
    }
}

TEST_CASE("simplify: hand-computed merge of two unit spheres", "[simplify]") {
    // Spheres of radius 1 at x = -2 and 2, opacity 0.5: equal weights, mean 0, covariance
    // I + diag(4, 0, 0): axes 1, 1, sqrt(5). Ink 2 x 0.5 x 4 pi over the merged area, which is
    // about 1.9 x 4 pi, so the opacity is 4 pi / area (about 0.53; no cap).
    GaussianCloud c(2, 0);
    c.means = {-2.f, 0.f, 0.f, 2.f, 0.f, 0.f};
    c.opacities = {0.5f, 0.5f};
    c.sh = {0.2f, 0.4f, 0.6f, 0.4f, 0.2f, 0.0f};
    const auto r = avsplat::simplify(c, count(1, SimplifyMethod::Merge));
    const GaussianCloud& g = r.cloud;
    for (int a = 0; a < 3; ++a) CHECK(g.means[a] == Approx(0.0).margin(1e-7));
    CHECK(g.scales[0] == Approx(1.0).epsilon(1e-6));
    CHECK(g.scales[1] == Approx(1.0).epsilon(1e-6));
    CHECK(g.scales[2] == Approx(std::sqrt(5.0)).epsilon(1e-6));
    const double area = area_ref(1.0, 1.0, std::sqrt(5.0));
    CHECK(g.opacities[0] == Approx(4.0 * kPi / area).epsilon(1e-6));
    CHECK(g.sh == std::vector<float>{0.3f, 0.3f, 0.3f});
    // The long axis is x: the rotation maps the third axis onto +-x.
    CHECK(std::abs(covariance_of(g, 0)(0, 0) - 5.0) < 1e-5);
}

TEST_CASE("simplify: the merge cost orders pairs as documented", "[simplify]") {
    using namespace avsplat::reduce_detail;
    GaussianCloud c(4, 0);
    // 0 and 1: identical but for the position along x; 2: same as 0 in another colour; 3: as 0
    // but transparent.
    c.means = {0, 0, 0, 0.1f, 0, 0, 0, 0, 0, 0, 0, 0};
    for (auto& s : c.scales) s = 0.1f;
    c.opacities = {0.9f, 0.9f, 0.9f, 0.01f};
    c.sh = {0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f, -0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f};
    MergeInput g[4];
    for (int i = 0; i < 4; ++i) g[i] = MergeInput::of(c, std::size_t(i));
    // Identical Gaussians cost only the ink the opacity cap loses, twice: 2 (1 - 1 / 1.8).
    const double same_place = merge_cost(g[0], g[0], &c.sh[0], &c.sh[0], 3);
    const double apart = merge_cost(g[0], g[1], &c.sh[0], &c.sh[3], 3);
    const double colour = merge_cost(g[0], g[2], &c.sh[0], &c.sh[6], 3);
    const double faint = merge_cost(g[0], g[3], &c.sh[0], &c.sh[9], 3);
    CHECK(same_place == Approx(2.0 * (1.0 - 1.0 / 1.8)).epsilon(1e-6));  // opacity 0.9f
    // Same place, same shape, ink below the cap, same colour: free.
    CHECK(faint == Approx(0.0).margin(1e-12));
    CHECK(apart > same_place);
    CHECK(colour > same_place);
    CHECK(faint < apart);
    CHECK(faint < colour);
    // Symmetric.
    CHECK(merge_cost(g[1], g[0], &c.sh[3], &c.sh[0], 3) == Approx(apart).epsilon(1e-12));
    // The colour term is 30 p0 p1 C0^2 2 |dsh|^2 (same shapes and places; DC coefficients weigh 2).
    CHECK(colour - same_place == Approx(30.0 * 0.25 * kShC0 * kShC0 * 2.0 * 1.0).epsilon(1e-9));
    // Runnalls' term for two spheres of radius 0.1 at distance 0.1 with equal weights: the merged
    // covariance is 0.01 I + 0.0025 e_x e_x^T, so G = ln(1.25) / 2 (the floor moves it by < 1e-3);
    // the merged area is larger than the ink needs, so L = 1 - min(1, W / S) S / W.
    const MergeInput merged_in = [&] {
        MergeInput m;
        m.cov = 0.01 * Eigen::Matrix3d::Identity();
        m.cov(0, 0) += 0.0025;
        return m;
    }();
    const double s_m = covariance_area(merged_in.cov);
    const double w01 = g[0].mass + g[1].mass;
    const double l = std::max(0.0, 1.0 - std::min(1.0, w01 / s_m) * s_m / w01);
    CHECK(apart == Approx(0.5 * std::log(1.25) + 2.0 * l).epsilon(2e-3));
}

TEST_CASE("simplify: counts meet the target (merge exactly, voxel within 2 %)", "[simplify]") {
    const GaussianCloud c = clustered(4000, 3);
    for (double ratio : {0.5, 0.25, 0.125, 0.0625}) {
        SimplifyOptions o;
        o.ratio = ratio;
        const std::size_t target = std::size_t(std::llround(ratio * 4000));
        o.method = SimplifyMethod::Merge;
        const auto m = avsplat::simplify(c, o);
        CHECK(m.output_count == target);
        CHECK(m.cloud.size() == target);
        CHECK(m.target_count == target);
        CHECK(std::isnan(m.voxel_size));
        avsplat::validate(m.cloud);
        o.method = SimplifyMethod::Voxel;
        const auto v = avsplat::simplify(c, o);
        INFO("ratio " << ratio << ": voxel gave " << v.output_count << " for " << target);
        CHECK(std::abs(double(v.output_count) - double(target)) <= 0.02 * double(target));
        CHECK(v.voxel_size > 0.0);
        CHECK(!v.cloud.has_confidence());  // derived from opacity, not kept
        avsplat::validate(v.cloud);
    }
}

TEST_CASE("simplify: merging conserves the ink of pairs that do not overlap", "[simplify]") {
    // Two small far-apart Gaussians: the merged one is large, so the ink cap is not reached.
    GaussianCloud c(2, 0);
    c.means = {0.f, 0.f, 0.f, 0.f, 0.f, 1.f};
    for (auto& s : c.scales) s = 0.01f;
    c.opacities = {0.7f, 0.2f};
    const auto r = avsplat::simplify(c, count(1, SimplifyMethod::Merge));
    const double ink_in = (0.7 + 0.2) * area_ref(0.01, 0.01, 0.01);
    const GaussianCloud& g = r.cloud;
    const double ink_out = double(g.opacities[0]) * area_ref(g.scales[0], g.scales[1], g.scales[2]);
    CHECK(ink_out == Approx(ink_in).epsilon(1e-5));
}

TEST_CASE("simplify: independent of input order and thread count", "[simplify]") {
    // Above kParallelMin (2^14), so the loops do go parallel.
    const GaussianCloud c = clustered(20000, 5, 400);
    std::vector<std::size_t> perm(c.size());
    std::iota(perm.begin(), perm.end(), std::size_t(0));
    std::shuffle(perm.begin(), perm.end(), std::mt19937(11));
    const GaussianCloud shuffled = avsplat::select(c, perm);
    const int threads = omp_get_max_threads();
    for (SimplifyMethod method : {SimplifyMethod::Merge, SimplifyMethod::Voxel}) {
        // 0.05: many Merge rounds.
        for (double ratio : {0.3, 0.05}) {
            SimplifyOptions o;
            o.ratio = ratio;
            o.method = method;
            omp_set_num_threads(1);
            const auto one = avsplat::simplify(c, o);
            omp_set_num_threads(std::max(2, threads));
            const auto many = avsplat::simplify(c, o);
            const auto perm_many = avsplat::simplify(shuffled, o);
            omp_set_num_threads(threads);
            INFO("ratio " << ratio);
            CHECK(same(one.cloud, many.cloud));
            CHECK(same(one.cloud, perm_many.cloud));
        }
    }
}

TEST_CASE("simplify: the canonical order sorts by every field, ties in x included", "[simplify]") {
    // x on a grid of 8 values (long runs of equal x: the order inside them comes from the other
    // fields), rows equal in the mean but not in opacity or colour, and exact duplicates.
    GaussianCloud c = clustered(20000, 5, 400);
    for (std::size_t i = 0; i < c.size(); ++i) c.means[3 * i] = std::round(c.means[3 * i] * 2.f) / 2.f + 0.f;  // no -0
    for (std::size_t i = 0; i + 1 < 600; i += 2) {
        for (int a = 0; a < 3; ++a) c.means[3 * (i + 1) + a] = c.means[3 * i + a];
        if (i % 4 == 0) {  // same mean, another opacity
            c.opacities[i + 1] = c.opacities[i] * 0.5f;
        } else {  // the whole row again
            std::copy_n(&c.scales[3 * i], 3, &c.scales[3 * (i + 1)]);
            std::copy_n(&c.rotations[4 * i], 4, &c.rotations[4 * (i + 1)]);
            c.opacities[i + 1] = c.opacities[i];
            const std::size_t k3 = std::size_t(c.sh_coeffs()) * 3;
            std::copy_n(&c.sh[k3 * i], k3, &c.sh[k3 * (i + 1)]);
        }
    }
    std::vector<std::size_t> perm(c.size());
    std::iota(perm.begin(), perm.end(), std::size_t(0));
    std::shuffle(perm.begin(), perm.end(), std::mt19937(12));
    const GaussianCloud shuffled = avsplat::select(c, perm);
    // Target N gives the input in canonical order: sorted by the bits of every field, mean first
    // (float order: the reference compares the values, -0 before +0 aside, absent here).
    const auto all = avsplat::simplify(c, count(c.size(), SimplifyMethod::Merge)).cloud;
    CHECK(same(all, avsplat::simplify(shuffled, count(c.size(), SimplifyMethod::Merge)).cloud));
    const std::size_t k3 = std::size_t(all.sh_coeffs()) * 3;
    auto row = [&](std::size_t i) {
        std::vector<float> r(&all.means[3 * i], &all.means[3 * i] + 3);
        r.insert(r.end(), &all.scales[3 * i], &all.scales[3 * i] + 3);
        r.insert(r.end(), &all.rotations[4 * i], &all.rotations[4 * i] + 4);
        r.push_back(all.opacities[i]);
        r.insert(r.end(), &all.sh[k3 * i], &all.sh[k3 * i] + k3);
        return r;
    };
    std::size_t unordered = 0;
    for (std::size_t i = 0; i + 1 < all.size(); ++i) unordered += row(i + 1) < row(i);
    CHECK(unordered == 0);
    // And so the merge of either input is the same, to the bit.
    for (double ratio : {0.3, 0.05}) {
        SimplifyOptions o;
        o.ratio = ratio;
        CHECK(same(avsplat::simplify(c, o).cloud, avsplat::simplify(shuffled, o).cloud));
    }
}

TEST_CASE("simplify: the result keeps the antialiasing flag", "[simplify]") {
    // Merged and fused Gaussians of an antialiased scene are rendered with its 2D filter too.
    GaussianCloud c = clustered(600, 13);
    for (bool flag : {true, false}) {
        c.antialiased = flag;
        for (SimplifyMethod method : {SimplifyMethod::Merge, SimplifyMethod::Voxel})
            for (std::size_t target : {std::size_t(150), c.size()}) {
                INFO("antialiased " << flag << ", method " << int(method) << ", target " << target);
                CHECK(avsplat::simplify(c, count(target, method)).cloud.antialiased == flag);
            }
    }
}

TEST_CASE("simplify: stiff cases", "[simplify]") {
    SECTION("all Gaussians in one point") {
        GaussianCloud c = clustered(300, 7);
        for (std::size_t i = 0; i < c.size(); ++i)
            for (int a = 0; a < 3; ++a) c.means[3 * i + a] = 0.25f;
        const auto m = avsplat::simplify(c, count(100, SimplifyMethod::Merge));
        CHECK(m.output_count == 100);
        avsplat::validate(m.cloud);
        for (std::size_t i = 0; i < m.cloud.size(); ++i) CHECK(m.cloud.means[3 * i] == Approx(0.25f));
        // One position: every voxel size gives one voxel, the closest the voxel method can get.
        const auto v = avsplat::simplify(c, count(100, SimplifyMethod::Voxel));
        CHECK(v.output_count == 1);
        avsplat::validate(v.cloud);
    }
    SECTION("scales of 1e-8 and 1e4") {
        GaussianCloud c = clustered(400, 8);
        for (std::size_t i = 0; i < c.size(); ++i)
            for (int a = 0; a < 3; ++a) c.scales[3 * i + a] = (i + std::size_t(a)) % 3 == 0 ? 1e4f : 1e-8f;
        // 50 and 20 (1/20): few and many rounds.
        for (std::size_t target : {50, 20})
            for (SimplifyMethod method : {SimplifyMethod::Merge, SimplifyMethod::Voxel}) {
                const auto r = avsplat::simplify(c, count(target, method));
                avsplat::validate(r.cloud);  // finite, scales >= 0, unit quaternions
                CHECK(std::abs(double(r.output_count) - double(target)) <= 1.0);
                for (float s : r.cloud.scales) CHECK(s <= 2e4f);
            }
    }
    SECTION("opacities 0 and 1") {
        GaussianCloud c = clustered(400, 9);
        for (std::size_t i = 0; i < c.size(); ++i) c.opacities[i] = i % 2 ? 1.f : 0.f;
        for (SimplifyMethod method : {SimplifyMethod::Merge, SimplifyMethod::Voxel}) {
            const auto r = avsplat::simplify(c, count(100, method));
            avsplat::validate(r.cloud);
            for (float o : r.cloud.opacities) CHECK((o >= 0.f && o <= 1.f));
        }
        // An opaque and a transparent Gaussian merge into the opaque one, unchanged but for
        // rounding: the transparent one has no weight.
        GaussianCloud pair = avsplat::select(c, {1, 2});
        REQUIRE(pair.opacities == std::vector<float>{1.f, 0.f});
        const auto r = avsplat::simplify(pair, count(1, SimplifyMethod::Merge));
        for (int a = 0; a < 3; ++a) CHECK(r.cloud.means[a] == Approx(pair.means[a]).epsilon(1e-6));
        CHECK((covariance_of(r.cloud, 0) - covariance_of(pair, 0)).norm() <= 1e-6 * covariance_of(pair, 0).norm());
        CHECK(r.cloud.opacities[0] == Approx(1.0f).epsilon(1e-6));
        for (int k = 0; k < 12; ++k) CHECK(r.cloud.sh[k] == Approx(pair.sh[k]).margin(1e-7));
    }
    SECTION("target 1 and target N") {
        const GaussianCloud c = clustered(257, 10);
        for (SimplifyMethod method : {SimplifyMethod::Merge, SimplifyMethod::Voxel}) {
            const auto one = avsplat::simplify(c, count(1, method));
            CHECK(one.output_count == 1);
            avsplat::validate(one.cloud);
            const auto all = avsplat::simplify(c, count(257, method));
            CHECK(all.output_count == 257);
            // The input, in canonical order: the same multiset of rows.
            std::vector<float> a = c.means, b = all.cloud.means;
            std::sort(a.begin(), a.end());
            std::sort(b.begin(), b.end());
            CHECK(a == b);
            SimplifyOptions o;
            o.ratio = 1.0;
            o.method = method;
            CHECK(avsplat::simplify(c, o).output_count == 257);
        }
    }
    SECTION("empty cloud and a single Gaussian") {
        CHECK(avsplat::simplify(GaussianCloud(0, 0), count(1, SimplifyMethod::Merge)).output_count == 0);
        CHECK(avsplat::simplify(GaussianCloud(1, 0), count(1, SimplifyMethod::Voxel)).output_count == 1);
    }
}

TEST_CASE("simplify: max_error keeps the rendered error under the bound", "[simplify]") {
    const GaussianCloud c = clustered(2000, 12, 30);
    std::vector<avsplat::Camera> cams = {
        avsplat::Camera::look_at({0, 0, 6}, {0, 0, 0}, {0, 1, 0}, 50.0, 64, 48),
        avsplat::Camera::look_at({5, 1, 3}, {0, 0, 0}, {0, 1, 0}, 50.0, 64, 48)};
    for (SimplifyMethod method : {SimplifyMethod::Merge, SimplifyMethod::Voxel}) {
        SimplifyOptions o;
        o.max_error = 0.02;
        o.method = method;
        const auto r = avsplat::simplify(c, o, cams);
        INFO("method " << int(method) << ": " << r.output_count << " Gaussians, error " << r.error);
        CHECK(r.error <= 0.02);
        CHECK(r.output_count < c.size());
        CHECK(r.searches >= 2);
        // The error reported is the error of the cloud returned.
        SimplifyOptions again;
        again.target_count = c.size();
        CHECK(avsplat::simplify(c, again, cams).error == 0.0);
    }
    SimplifyOptions o;
    o.max_error = 0.01;
    CHECK_THROWS_WITH(avsplat::simplify(c, o), Catch::Contains("max_error needs cameras"));
}

TEST_CASE("simplify: bad options and clouds name the field", "[simplify]") {
    const GaussianCloud c = clustered(10, 13);
    SimplifyOptions none;
    CHECK_THROWS_WITH(avsplat::simplify(c, none), Catch::Contains("exactly one of"));
    SimplifyOptions two;
    two.ratio = 0.5;
    two.target_count = 3;
    CHECK_THROWS_AS(avsplat::simplify(c, two), std::invalid_argument);
    SimplifyOptions bad;
    bad.ratio = 1.5;
    CHECK_THROWS_WITH(avsplat::simplify(c, bad), Catch::Contains("SimplifyOptions.ratio"));
    bad.ratio.reset();
    bad.target_count = 0;
    CHECK_THROWS_WITH(avsplat::simplify(c, bad), Catch::Contains("SimplifyOptions.target_count"));
    GaussianCloud nan = c;
    nan.means[3 * 4 + 1] = std::nanf("");
    CHECK_THROWS_WITH(avsplat::simplify(nan, count(5, SimplifyMethod::Merge)), Catch::Contains("means[4"));
}

namespace {

// One round's pairs by brute force: every distance, the `neighbours` nearest of each (ties by the nearer
// index, then the smaller), the
// union of the lists, every candidate priced with merge_cost, one full sort, the greedy scan.
std::vector<std::uint32_t> round_pairs_ref(const GaussianCloud& c, const std::vector<avsplat::reduce_detail::MergeInput>& g,
                                           std::size_t needed, std::size_t neighbours) {
    using namespace avsplat::reduce_detail;
    const std::size_t n = c.size(), k = std::min<std::size_t>(neighbours, n - 1), k3 = std::size_t(c.sh_coeffs()) * 3;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs;
    for (std::size_t i = 0; i < n; ++i) {
        std::vector<std::pair<double, std::uint32_t>> d;
        for (std::size_t j = 0; j < n; ++j) {
            if (j == i) continue;
            double s = 0.0;
            for (int a = 0; a < 3; ++a) {
                const double x = double(c.means[3 * i + a]) - double(c.means[3 * j + a]);
                s += x * x;
            }
            d.emplace_back(s, std::uint32_t(j));
        }
        auto gap = [i](std::uint32_t j) { return j > i ? j - i : std::uint32_t(i) - j; };
        std::partial_sort(d.begin(), d.begin() + std::ptrdiff_t(k), d.end(), [&](const auto& x, const auto& y) {
            return std::make_tuple(x.first, gap(x.second), x.second) < std::make_tuple(y.first, gap(y.second), y.second);
        });
        for (std::size_t t = 0; t < k; ++t) {
            pairs.emplace_back(std::min<std::uint32_t>(std::uint32_t(i), d[t].second),
                               std::max<std::uint32_t>(std::uint32_t(i), d[t].second));
        }
    }
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    std::vector<std::tuple<double, std::uint32_t, std::uint32_t>> edges;
    for (const auto& [a, b] : pairs)
        edges.emplace_back(merge_cost(g[a], g[b], &c.sh[k3 * a], &c.sh[k3 * b], k3), a, b);
    std::sort(edges.begin(), edges.end());
    std::vector<std::uint32_t> partner(n, kNone);
    std::size_t merged = 0;
    for (const auto& [cost, a, b] : edges) {
        if (merged >= needed) break;
        if (partner[a] != kNone || partner[b] != kNone) continue;
        partner[a] = b;
        partner[b] = a;
        ++merged;
    }
    return partner;
}

}  // namespace

TEST_CASE("simplify: a merge round takes the pairs of the brute-force round", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Random clouds, and one full of equal distances: the all-kNN tree, the lower bounds, the
    // radix sort and the lazily priced greedy scan take exactly the brute-force pairs, for any
    // number of threads and any share of the cloud.
    const int threads = omp_get_max_threads();
    for (unsigned seed : {1u, 2u, 3u, 4u}) {
        GaussianCloud c = clustered(seed == 3 ? 16500 : 1500, seed, seed == 2 ? 3 : 40);
        // Seed 4: means on a grid of 0.02 (equal distances everywhere, and coincident means):
        // the neighbours are then decided by index, the pairs by (cost, a, b).
        if (seed == 4)
            for (float& x : c.means) x = 0.02f * std::round(x / 0.02f);
        std::vector<MergeInput> g(c.size());
        for (std::size_t i = 0; i < c.size(); ++i) g[i] = MergeInput::of(c, i);
        // 8 and 12 neighbours: merge_to_count's first and later rounds; 16: splat-transform's.
        for (std::size_t k : {8, 12, 16})
        for (double share : {0.05, 0.4, 0.5}) {
            if (seed == 3 && k != 12) continue;  // the large cloud: once (its brute force is slow)
            const std::size_t needed = std::size_t(share * double(c.size()));
            const std::vector<std::uint32_t> ref = round_pairs_ref(c, g, needed, k);
            omp_set_num_threads(1);
            const std::vector<std::uint32_t> one = round_pairs(c, g, needed, k);
            omp_set_num_threads(std::max(2, threads));
            const std::vector<std::uint32_t> many = round_pairs(c, g, needed, k);
            omp_set_num_threads(threads);
            INFO("seed " << seed << ", neighbours " << k << ", share " << share);
            CHECK(one == ref);
            CHECK(many == ref);
            const auto merged = std::size_t(std::count_if(ref.begin(), ref.end(), [](std::uint32_t p) { return p != kNone; })) / 2;
            // Half the cloud cannot always be paired among the neighbours; below that, exactly `needed`.
            if (share < 0.5) CHECK(merged == needed);
            CHECK(merged <= needed);
        }
    }
}

TEST_CASE("simplify: max_error reports each simplification it tries to the progress callback", "[simplify]") {
    const GaussianCloud c = clustered(600, 6, 30);
    const std::vector<avsplat::Camera> cams = {
        avsplat::Camera::look_at({0, 0, 6}, {0, 0, 0}, {0, 1, 0}, 50.0, 32, 24)};
    SimplifyOptions o;
    o.max_error = 0.02;
    std::vector<int> calls;
    o.progress = [&calls](int tried, int most) {
        CHECK(most == avsplat::kMaxErrorSearches);
        calls.push_back(tried);
    };
    const auto r = avsplat::simplify(c, o, cams);
    REQUIRE(int(calls.size()) == r.searches);
    REQUIRE(r.searches >= 2);
    for (std::size_t k = 0; k < calls.size(); ++k) CHECK(calls[k] == int(k) + 1);
    CHECK(r.searches <= avsplat::kMaxErrorSearches);
    // Watching does not change the result.
    SimplifyOptions plain = o;
    plain.progress = nullptr;
    CHECK(avsplat::simplify(c, plain, cams).output_count == r.output_count);
}
