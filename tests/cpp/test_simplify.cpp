// simplify (reduce/simplify.h): the pairwise moment match against its closed form written here,
// budgets, determinism and the stiff cases.
#include "avsplat/reduce/simplify.h"

#include "common/all_knn.h"
#include "reduce/moment_merge.h"
#include "reduce/simplify_methods.h"

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

namespace {

constexpr double kPi = 3.14159265358979323846;

// Thomsen's ellipsoid surface area written out again for the reference.
double area_ref(double a, double b, double c) {
    const double p = 1.6075;
    return 4.0 * kPi * std::pow((std::pow(a * b, p) + std::pow(a * c, p) + std::pow(b * c, p)) / 3.0, 1.0 / p);
}

Eigen::Matrix3d covariance_of(const GaussianCloud& c, std::size_t i) {
    const Eigen::Quaterniond q(c.rotations[4 * i], c.rotations[4 * i + 1], c.rotations[4 * i + 2], c.rotations[4 * i + 3]);
    const Eigen::Matrix3d r = q.normalized().toRotationMatrix();
    const Eigen::Vector3d s(c.scales[3 * i], c.scales[3 * i + 1], c.scales[3 * i + 2]);
    return r * s.cwiseProduct(s).asDiagonal() * r.transpose();
}

// Clusters of Gaussians like a fused scene: n Gaussians around `clusters` centres, SH degree 1.
GaussianCloud clustered(std::size_t n, unsigned seed, int clusters = 50) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f), pos(0.f, 1.f);
    std::normal_distribution<float> nrm(0.f, 1.f);
    std::vector<Eigen::Vector3f> centres(static_cast<std::size_t>(clusters));
    for (auto& c : centres) c = Eigen::Vector3f(u(rng), u(rng), u(rng)) * 2.f;
    GaussianCloud c(n, 1);
    for (std::size_t i = 0; i < n; ++i) {
        const Eigen::Vector3f& m = centres[i % centres.size()];
        for (int a = 0; a < 3; ++a) {
            c.means[3 * i + a] = m[a] + 0.05f * nrm(rng);
            c.scales[3 * i + a] = 0.005f + 0.02f * pos(rng);
        }
        Eigen::Vector4f q(nrm(rng), nrm(rng), nrm(rng), nrm(rng));
        q.normalize();
        for (int a = 0; a < 4; ++a) c.rotations[4 * i + a] = q[a];
        c.opacities[i] = 0.05f + 0.9f * pos(rng);
        for (std::size_t k = 0; k < 12; ++k) c.sh[12 * i + k] = 0.5f * u(rng);
    }
    return c;
}

// clustered() with every third Gaussian flat, every fifth a needle and every seventh of opacity 0
// or 1: the shapes whose merge costs take the stiff paths.
GaussianCloud stiff_clustered(std::size_t n, unsigned seed, int clusters, unsigned opacity_seed) {
    GaussianCloud c = clustered(n, seed, clusters);
    std::mt19937 rng(opacity_seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (std::size_t i = 0; i < c.size(); i += 3) c.scales[3 * i + std::size_t(i % 3)] *= 1e-3f;  // flat
    for (std::size_t i = 1; i < c.size(); i += 5) c.scales[3 * i + std::size_t(i % 3)] *= 50.f;   // needles
    for (std::size_t i = 2; i < c.size(); i += 7) c.opacities[i] = u(rng) < 0.5f ? 0.f : 1.f;
    return c;
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
    // The colour term is 30 p0 p1 C0^2 |dsh|^2 (same shapes and places).
    CHECK(colour - same_place == Approx(30.0 * 0.25 * kShC0 * kShC0 * 1.0).epsilon(1e-9));
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
        SimplifyOptions o;
        o.ratio = 0.3;
        o.method = method;
        omp_set_num_threads(1);
        const auto one = avsplat::simplify(c, o);
        omp_set_num_threads(std::max(2, threads));
        const auto many = avsplat::simplify(c, o);
        const auto perm_many = avsplat::simplify(shuffled, o);
        omp_set_num_threads(threads);
        CHECK(same(one.cloud, many.cloud));
        CHECK(same(one.cloud, perm_many.cloud));
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
        for (SimplifyMethod method : {SimplifyMethod::Merge, SimplifyMethod::Voxel}) {
            const auto r = avsplat::simplify(c, count(50, method));
            avsplat::validate(r.cloud);  // finite, scales >= 0, unit quaternions
            CHECK(std::abs(double(r.output_count) - 50.0) <= 1.0);
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

// The merge cost written with matrices (Eigen's determinant and eigen solver, double pow): the
// reference for merge_cost, which works from the invariants and skips the eigenvalues when it can.
double merge_cost_ref(const avsplat::reduce_detail::MergeInput& a, const avsplat::reduce_detail::MergeInput& b,
                      const float* sh_a, const float* sh_b, std::size_t k3) {
    using namespace avsplat::reduce_detail;
    const auto [pa, pb] = pair_weights(a, b);
    Eigen::Vector3d mean;
    Eigen::Matrix3d cov;
    moment_match(a, b, pa, pb, mean, cov);
    const Eigen::Matrix3d floor = (1e-4 * cov.trace() / 3.0 + 1e-300) * Eigen::Matrix3d::Identity();
    const double g = std::max(0.0, 0.5 * (std::log((cov + floor).determinant()) - pa * std::log((a.cov + floor).determinant()) -
                                          pb * std::log((b.cov + floor).determinant())));
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov, Eigen::EigenvaluesOnly);
    const Eigen::Vector3d ev = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
    const double area = area_ref(ev[0], ev[1], ev[2]);
    const double w = a.mass + b.mass;
    const double l = w > 0.0 && area > 0.0 ? std::max(0.0, 1.0 - std::min(1.0, w / area) * area / w) : 0.0;
    double colour = 0.0;
    for (std::size_t c = 0; c < k3; ++c) colour += (double(sh_a[c]) - double(sh_b[c])) * (double(sh_a[c]) - double(sh_b[c]));
    return g + 2.0 * l + 30.0 * pa * pb * kShC0 * kShC0 * colour;
}

// One round's pairs by brute force: every distance, the 16 nearest of each (ties by the nearer
// index, then the smaller), the
// union of the lists, every candidate priced with merge_cost, one full sort, the greedy scan.
std::vector<std::uint32_t> round_pairs_ref(const GaussianCloud& c, const std::vector<avsplat::reduce_detail::MergeInput>& g,
                                           std::size_t needed) {
    using namespace avsplat::reduce_detail;
    const std::size_t n = c.size(), k = std::min<std::size_t>(16, n - 1), k3 = std::size_t(c.sh_coeffs()) * 3;
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
        for (std::size_t t = 0; t < k; ++t)
            pairs.emplace_back(std::min<std::uint32_t>(std::uint32_t(i), d[t].second),
                               std::max<std::uint32_t>(std::uint32_t(i), d[t].second));
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

TEST_CASE("simplify: merge_cost from the invariants matches the matrix form", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Clustered Gaussians (overlapping, L > 0 for many pairs), needles and flat ones, far pairs.
    const GaussianCloud c = stiff_clustered(600, 21, 20, 4);
    std::vector<MergeInput> g(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) g[i] = MergeInput::of(c, i);
    int with_loss = 0;  // pairs whose merged area is below their ink: the eigenvalue path
    for (std::size_t i = 0; i < c.size(); ++i)
        for (std::size_t j : {i + 1, i + 20, i + 97}) {
            if (j >= c.size()) continue;
            const double fast = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            const double ref = merge_cost_ref(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            INFO("pair " << i << ", " << j);
            // The merged area in float: L (in [0, 1], weighted 2) to 1e-6; the rest to rounding.
            CHECK(fast == Approx(ref).epsilon(1e-9).margin(2e-6));
            Eigen::Vector3d mean;
            Eigen::Matrix3d cov;
            const auto [pa, pb] = pair_weights(g[i], g[j]);
            moment_match(g[i], g[j], pa, pb, mean, cov);
            with_loss += covariance_area(cov) < g[i].mass + g[j].mass;
        }
    CHECK(with_loss > 0);
}

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
        for (double share : {0.05, 0.4, 0.5}) {
            const std::size_t needed = std::size_t(share * double(c.size()));
            const std::vector<std::uint32_t> ref = round_pairs_ref(c, g, needed);
            omp_set_num_threads(1);
            const std::vector<std::uint32_t> one = round_pairs(c, g, needed);
            omp_set_num_threads(std::max(2, threads));
            const std::vector<std::uint32_t> many = round_pairs(c, g, needed);
            omp_set_num_threads(threads);
            INFO("seed " << seed << ", share " << share);
            CHECK(one == ref);
            CHECK(many == ref);
            const auto merged = std::size_t(std::count_if(ref.begin(), ref.end(), [](std::uint32_t p) { return p != kNone; })) / 2;
            // Half the cloud cannot always be paired among 16 neighbours; below that, exactly `needed`.
            if (share < 0.5) CHECK(merged == needed);
            CHECK(merged <= needed);
        }
    }
}

namespace {

// The k nearest others of point i by brute force: (squared distance in double, index), smallest
// first, as a sorted list of indices.
std::vector<std::uint32_t> knn_ref(const std::vector<float>& p, std::size_t i, std::size_t k) {
    const std::size_t n = p.size() / 3;
    std::vector<std::pair<double, std::uint32_t>> d;
    for (std::size_t j = 0; j < n; ++j) {
        if (j == i) continue;
        double s = 0.0;
        for (int a = 0; a < 3; ++a) {
            const double x = double(p[3 * j + a]) - double(p[3 * i + a]);
            s += x * x;
        }
        d.emplace_back(s, std::uint32_t(j));
    }
    k = std::min(k, d.size());
    // Ties by the nearer index, then the smaller.
    auto gap = [i](std::uint32_t j) { return j > i ? j - i : i - j; };
    std::partial_sort(d.begin(), d.begin() + std::ptrdiff_t(k), d.end(), [&](const auto& x, const auto& y) {
        return std::make_tuple(x.first, gap(x.second), x.second) < std::make_tuple(y.first, gap(y.second), y.second);
    });
    std::vector<std::uint32_t> out;
    for (std::size_t t = 0; t < k; ++t) out.push_back(d[t].second);
    std::sort(out.begin(), out.end());
    return out;
}

void check_all_knn(const std::vector<float>& p, std::size_t k) {
    const std::size_t n = p.size() / 3;
    const avsplat::detail::AllKnnTree tree(p.data(), n, "test");
    const std::size_t kk = std::min(k, n - 1);
    std::vector<std::uint32_t> out(n * kk, 0xffffffffu);
    for (std::size_t l = 0; l < tree.leaf_count(); ++l) tree.all_knn_leaf(l, k, out.data());
    for (std::size_t i = 0; i < n; ++i) {
        std::vector<std::uint32_t> got(out.begin() + std::ptrdiff_t(i * kk), out.begin() + std::ptrdiff_t((i + 1) * kk));
        std::sort(got.begin(), got.end());
        INFO("n " << n << ", k " << k << ", point " << i);
        REQUIRE(got == knn_ref(p, i, k));
    }
}

}  // namespace

TEST_CASE("simplify: the all-kNN tree finds the brute-force neighbours, ties by index", "[simplify]") {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    std::normal_distribution<float> nrm(0.f, 1.f);
    for (std::size_t n : {1u, 2u, 3u, 16u, 17u, 33u, 500u, 3000u}) {
        // Uniform in a cube; on a surface (a sphere: flat neighbourhoods, like a scene); on a
        // grid (equal distances everywhere, decided by index); with every point doubled.
        std::vector<float> cube(3 * n), sphere(3 * n), grid(3 * n), twice(3 * n);
        for (std::size_t i = 0; i < n; ++i) {
            Eigen::Vector3f v(nrm(rng), nrm(rng), nrm(rng));
            v.normalize();
            for (int a = 0; a < 3; ++a) {
                cube[3 * i + a] = u(rng);
                sphere[3 * i + a] = v[a];
                grid[3 * i + a] = float(int(8.f * (u(rng) + 1.f)));
                twice[3 * i + a] = cube[3 * (i / 2) + a];
            }
        }
        for (std::size_t k : {1u, 4u, 16u, 32u}) {
            check_all_knn(cube, k);
            check_all_knn(sphere, k);
            check_all_knn(grid, k);
            check_all_knn(twice, k);
        }
    }
    // All points equal: the k smallest other indices. One point: nothing to find.
    check_all_knn(std::vector<float>(3 * 100, 0.25f), 16);
    check_all_knn(std::vector<float>(3 * 3000, 0.25f), 16);
    {
        // Many equal points: a leaf whose index range cannot beat a query's k-th is skipped, so
        // this is linear (it visited every leaf from every leaf before: 10^10 distances, tens
        // of seconds). Each point's neighbours are the 16 nearest other indices.
        const std::size_t n = 100000;
        const std::vector<float> same(3 * n, -3.5f);
        const avsplat::detail::AllKnnTree tree(same.data(), n, "test");
        std::vector<std::uint32_t> out(n * 16);
        for (std::size_t l = 0; l < tree.leaf_count(); ++l) tree.all_knn_leaf(l, 16, out.data());
        for (std::size_t i = 0; i < n; i += 997) {
            std::vector<std::uint32_t> got(out.begin() + std::ptrdiff_t(i * 16), out.begin() + std::ptrdiff_t(i * 16 + 16));
            std::sort(got.begin(), got.end());
            std::vector<std::uint32_t> all(n);
            std::iota(all.begin(), all.end(), std::uint32_t(0));
            auto gap = [i](std::uint32_t j) { return j > i ? j - i : std::uint32_t(i) - j; };
            std::partial_sort(all.begin(), all.begin() + 17, all.end(), [&](std::uint32_t x, std::uint32_t y) {
                return std::make_pair(gap(x), x) < std::make_pair(gap(y), y);
            });
            std::vector<std::uint32_t> want(all.begin() + 1, all.begin() + 17);  // all[0] is i
            std::sort(want.begin(), want.end());
            REQUIRE(got == want);
        }
    }
    const std::vector<float> one{1.f, 2.f, 3.f};
    const avsplat::detail::AllKnnTree single(one.data(), 1, "test");
    REQUIRE(single.leaf_count() == 1);
    single.all_knn_leaf(0, 16, nullptr);  // k = min(16, n - 1) = 0: writes nothing
    std::vector<std::uint32_t> out(16 * 40);
    REQUIRE_THROWS_AS(avsplat::detail::AllKnnTree(one.data(), 1, "test").all_knn_leaf(0, 33, out.data()),
                      std::invalid_argument);
}

TEST_CASE("simplify: the cost's lower bound is below merge_cost and close to it for cheap pairs", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Clustered Gaussians with flat, needle, opaque and transparent ones, and stiff scales.
    GaussianCloud c = stiff_clustered(800, 23, 25, 5);
    for (std::size_t i = 4; i < c.size(); i += 53)
        for (int a = 0; a < 3; ++a) c.scales[3 * i + std::size_t(a)] = (i / 53) % 2 ? 1e-8f : 1e4f;
    for (std::size_t i = 6; i < c.size(); i += 61) c.sh[12 * i] = c.sh[12 * (i - 1)];
    std::vector<MergeInput> g(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) g[i] = MergeInput::of(c, i);
    std::size_t cheap = 0, tight = 0, pairs = 0;
    for (std::size_t i = 0; i < c.size(); ++i)
        for (std::size_t j : {i, i + 1, i + 25, i + 26, i + 97}) {
            if (j >= c.size()) continue;
            const double cost = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            const double lb = merge_cost_lower_bound(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            INFO("pair " << i << ", " << j << ": cost " << cost << ", bound " << lb);
            REQUIRE(lb >= 0.0);
            REQUIRE(lb <= cost);
            ++pairs;
            // The pairs a round takes are the cheap ones: there the bound should be near the cost
            // (G's bound is within a few % of G below G = 0.5; L, left out, is often 0).
            if (cost < 0.5) {
                ++cheap;
                tight += lb >= 0.7 * cost;
            }
        }
    CHECK(pairs > 3000);
    CHECK(cheap > 300);
    CHECK(double(tight) >= 0.8 * double(cheap));
}

TEST_CASE("simplify: the lower bound holds on stiff pairs and counts the lost ink", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Random pairs near each other: spheres, flat surfels, needles, points (zero scales) and
    // scales of 1e-8 to 1e4, opacities 0, 1 and between, so that merged needles (area 0, where
    // merge_cost sets L = 0) and overlapping opaque pairs (L near 1/2) both occur.
    std::mt19937 rng(77);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    std::normal_distribution<float> nrm(0.f, 1.f);
    const std::size_t n = 20000;
    GaussianCloud c(n, 1);
    for (std::size_t i = 0; i < n; ++i) {
        const float scale = std::pow(10.f, -8.f + 12.f * u(rng));
        const std::size_t anchor = i & ~std::size_t(1);  // pairs (2m, 2m + 1) share a centre
        std::mt19937 at{unsigned(anchor)};
        std::uniform_real_distribution<float> ua(-10.f, 10.f);
        for (int a = 0; a < 3; ++a) c.means[3 * i + a] = ua(at) + (u(rng) < 0.3f ? 0.f : scale * nrm(rng));
        const int shape = int(i / 2 % 5);
        for (int a = 0; a < 3; ++a) {
            float s = scale * (0.5f + u(rng));
            if (shape == 1 && a == 0) s *= 1e-4f;  // flat
            if (shape == 2 && a != 0) s = 0.f;     // needle: two zero axes
            if (shape == 3) s = 0.f;               // point
            c.scales[3 * i + a] = s;
        }
        for (int a = 0; a < 4; ++a) c.rotations[4 * i + a] = nrm(rng);
        const float o = u(rng);
        c.opacities[i] = o < 0.3f ? 1.f : (o < 0.4f ? 0.f : u(rng));
        for (int k = 0; k < 12; ++k) c.sh[12 * i + k] = u(rng) < 0.5f ? 0.f : nrm(rng);
    }
    // Identical opaque spheres as the last pair: W = 2 x area, so L = 1/2 and cost = 2 L = 1.
    for (int a = 0; a < 3; ++a) {
        c.means[3 * (n - 1) + a] = c.means[3 * (n - 2) + a] = 1.f;
        c.scales[3 * (n - 1) + a] = c.scales[3 * (n - 2) + a] = 0.5f;
    }
    for (int a = 0; a < 4; ++a) c.rotations[4 * (n - 1) + a] = c.rotations[4 * (n - 2) + a] = a == 0 ? 1.f : 0.f;
    c.opacities[n - 1] = c.opacities[n - 2] = 1.f;
    for (int k = 0; k < 12; ++k) c.sh[12 * (n - 1) + k] = c.sh[12 * (n - 2) + k] = 0.f;

    std::vector<MergeInput> g(n);
    for (std::size_t i = 0; i < n; ++i) g[i] = MergeInput::of(c, i);
    std::size_t lossy = 0, lossy_tight = 0;
    for (std::size_t i = 0; i + 1 < n; ++i)
        for (std::size_t j : {i + 1, i + 2}) {
            if (j >= n) continue;
            const double cost = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            const double lb = merge_cost_lower_bound(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            INFO("pair " << i << ", " << j << ": cost " << cost << ", bound " << lb);
            REQUIRE(lb >= 0.0);
            REQUIRE(lb <= cost);
            // Where most of the cost is lost ink, the bound sees it (G's bound and C alone
            // would stay far below).
            const PairTerms t = pair_terms(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            const double g_part = 0.5 * (std::log(t.fd) - t.pa * std::log(t.fda) - t.pb * std::log(t.fdb));
            if (std::isfinite(cost) && cost - std::max(0.0, g_part) - t.colour > 0.2) {
                ++lossy;
                lossy_tight += lb >= std::max(0.0, g_part) + t.colour + 0.1;
            }
        }
    const double cost = merge_cost(g[n - 2], g[n - 1], &c.sh[12 * (n - 2)], &c.sh[12 * (n - 1)], 12);
    const double lb = merge_cost_lower_bound(g[n - 2], g[n - 1], &c.sh[12 * (n - 2)], &c.sh[12 * (n - 1)], 12);
    CHECK(cost == Approx(1.0).epsilon(1e-5));
    CHECK(lb == Approx(1.0).epsilon(1e-3));
    CHECK(lossy > 100);
    INFO("lossy " << lossy << ", tight " << lossy_tight);
    CHECK(double(lossy_tight) >= 0.5 * double(lossy));
}
