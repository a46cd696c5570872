// The merge cost of simplify's Merge method (reduce/moment_merge.h): from the invariants against
// the matrix form written here, and its lower bound (the greedy rounds' lazy pricing) against it.
#include "reduce/merge_cost_bound.h"
#include "reduce/moment_merge.h"
#include "reduce/simplify_methods.h"
#include "simplify_clouds.h"

#include <catch2/catch.hpp>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

using avsplat::GaussianCloud;
using simplify_test::area_ref;
using simplify_test::clustered;
using simplify_test::stiff_clustered;

namespace {

// The merge cost written with matrices (Eigen's determinant, inverse and eigen solver, double pow):
// the reference for merge_cost, which works from the invariants and skips the eigenvalues when it
// can.
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
    // The three DC coefficients (the first, SH degree 0 first) weigh 2, the higher bands 1.
    double colour = 0.0;
    for (std::size_t c = 0; c < k3; ++c)
        colour += (c < 3 ? 2.0 : 1.0) * (double(sh_a[c]) - double(sh_b[c])) * (double(sh_a[c]) - double(sh_b[c]));
    return g + 2.0 * l + 30.0 * pa * pb * kShC0 * kShC0 * colour;
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

TEST_CASE("simplify: log_series_below is below std::log and within kLogSeriesRest of it", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Mantissas from 1 to just below 2 (where the cut series is furthest below ln m), exponents
    // over the whole normal range (the smallest normal, the largest finite).
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> um(1.0, 2.0);
    std::uniform_int_distribution<int> ue(-1022, 1023);
    std::vector<double> xs = {1.0, 2.0, 0.5, std::nextafter(2.0, 0.0), std::numeric_limits<double>::min(),
                              std::numeric_limits<double>::max(), 3.0, 1e-300, 1e300};
    for (int t = 0; t < 100000; ++t) xs.push_back(std::ldexp(um(rng), ue(rng)));
    double widest = 0.0;
    for (double x : xs) {
        INFO("x = " << x);
        REQUIRE(positive_normal(x));
        const double ln = std::log(x), lo = log_series_below(x);
        REQUIRE(lo <= ln + 1e-12);
        REQUIRE(lo >= ln - kLogSeriesRest - 1e-12);
        widest = std::max(widest, ln - lo);
    }
    CHECK(log_series_below(1.0) == 0.0);
    // The constant is the series' rest near m = 2, not a loose margin.
    CHECK(widest > 0.95 * kLogSeriesRest);
    for (double x : {0.0, -1.0, std::numeric_limits<double>::denorm_min(), HUGE_VAL, std::nan("")})
        CHECK_FALSE(positive_normal(x));
}

TEST_CASE("simplify: the cost's lower bound is within kLogSeriesRest of G + C", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Random nearby pairs of every shape and size (the lower bound's G from three series against
    // merge_cost's three logarithms): the bound is G + C less at most kLogSeriesRest and the
    // margin, plus its share of L (>= 0). Jensen's bound, used before, was below G by 0.37 on
    // average over the pairs a round prices.
    GaussianCloud c = stiff_clustered(1200, 31, 40, 6);
    std::vector<MergeInput> g(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) g[i] = MergeInput::of(c, i);
    std::size_t pairs = 0, unequal = 0;
    for (std::size_t i = 0; i < c.size(); ++i)
        for (std::size_t j : {i + 1, i + 3, i + 40, i + 41}) {
            if (j >= c.size()) continue;
            const PairTerms t = pair_terms(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            if (!positive_normal(t.fd) || !positive_normal(t.fda) || !positive_normal(t.fdb)) continue;
            const double g_exact = std::max(0.0, 0.5 * (std::log(t.fd) - t.pa * std::log(t.fda) - t.pb * std::log(t.fdb)));
            const double lb = merge_cost_lower_bound(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            const double cost = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            INFO("pair " << i << ", " << j << ": G " << g_exact << ", C " << t.colour << ", bound " << lb);
            REQUIRE(lb <= cost);
            REQUIRE(lb >= g_exact + t.colour - kLogSeriesRest - 1e-10);
            ++pairs;
            // Pairs whose floored determinants differ 100-fold: where Jensen's bound was loose.
            unequal += std::max(t.fda, t.fdb) > 100.0 * std::min(t.fda, t.fdb) && g_exact > 0.01;
        }
    CHECK(pairs > 3000);
    CHECK(unequal > 100);
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
