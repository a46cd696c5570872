// The merge cost of simplify's Merge method (reduce/moment_merge.h): from the invariants against
// the matrix form written here, its field term against a numerical integral and its weight, and
// its lower bound (the greedy rounds' lazy pricing) against it.
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

// The integral of the product of the unnormalised kernels with covariances x, y whose centres are
// d apart, with Eigen's inverse and determinants: (2 pi)^(3/2) sqrt(|x| |y| / |x + y|)
// exp(-d^T (x + y)^-1 d / 2).
double kernel_product_ref(const Eigen::Matrix3d& x, const Eigen::Matrix3d& y, const Eigen::Vector3d& d) {
    const Eigen::Matrix3d s = x + y;
    return std::pow(2.0 * simplify_test::kPi, 1.5) * std::sqrt(x.determinant() * y.determinant() / s.determinant()) *
           std::exp(-0.5 * d.dot(s.inverse() * d));
}

// The merge cost written with matrices (Eigen's determinant, inverse and eigen solver, double pow):
// the reference for merge_cost, which works from the invariants and skips the eigenvalues when it
// can. `field_weight`: the weight of F, the squared L2 distance of the amplitude fields.
double merge_cost_ref(const avsplat::reduce_detail::MergeInput& a, const avsplat::reduce_detail::MergeInput& b,
                      const float* sh_a, const float* sh_b, std::size_t k3, double field_weight = 0.0) {
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
    double f = 0.0;
    if (field_weight > 0.0) {
        const double om = area > 0.0 ? std::min(1.0, w / area) : std::max(a.opacity, b.opacity);
        // F's floor: 1e-6 of the merged size.
        const Eigen::Matrix3d ff = (1e-6 * cov.trace() / 3.0 + 1e-300) * Eigen::Matrix3d::Identity();
        const Eigen::Matrix3d sa = a.cov + ff, sb = b.cov + ff, sm = cov + ff;
        const double oa = a.opacity, ob = b.opacity;
        auto self = [](const Eigen::Matrix3d& x) { return std::pow(simplify_test::kPi, 1.5) * std::sqrt(x.determinant()); };
        f = oa * oa * self(sa) + ob * ob * self(sb) + om * om * self(sm) +
            2.0 * (oa * ob * kernel_product_ref(sa, sb, a.mean - b.mean) - oa * om * kernel_product_ref(sa, sm, a.mean - mean) -
                   ob * om * kernel_product_ref(sb, sm, b.mean - mean));
        f = field_weight * std::max(0.0, f);
    }
    return g + 2.0 * l + 30.0 * pa * pb * kShC0 * kShC0 * colour + f;
}

}  // namespace

TEST_CASE("simplify: merge_cost from the invariants matches the matrix form", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Clustered Gaussians (overlapping, L > 0 for many pairs), needles and flat ones, far pairs.
    const GaussianCloud c = stiff_clustered(600, 21, 20, 4);
    std::vector<MergeInput> g(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) g[i] = MergeInput::of(c, i);
    int with_loss = 0;  // pairs whose merged area is below their ink: the eigenvalue path
    // With the field term F as simplify weighs it at 1/16 (and 100 times that, so that F decides).
    const double fw = field_weight(g, c.size() / 16);
    REQUIRE(fw > 0.0);
    int field_counts = 0;  // pairs where F is at least a tenth of the cost
    for (std::size_t i = 0; i < c.size(); ++i)
        for (std::size_t j : {i + 1, i + 20, i + 97}) {
            if (j >= c.size()) continue;
            const double fast = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            const double ref = merge_cost_ref(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            INFO("pair " << i << ", " << j);
            // The merged area in float: L (in [0, 1], weighted 2) to 1e-6; the rest to rounding.
            CHECK(fast == Approx(ref).epsilon(1e-9).margin(2e-6));
            for (double w : {fw, 100.0 * fw}) {
                const double fast_f = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12, w);
                const double ref_f = merge_cost_ref(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12, w);
                INFO("field weight " << w);
                // F also reads the merged opacity from the float area (relative 1e-6).
                CHECK(fast_f == Approx(ref_f).epsilon(1e-5).margin(2e-6));
                field_counts += ref_f - ref >= 0.1 * ref_f;
            }
            Eigen::Vector3d mean;
            Eigen::Matrix3d cov;
            const auto [pa, pb] = pair_weights(g[i], g[j]);
            moment_match(g[i], g[j], pa, pb, mean, cov);
            with_loss += covariance_area(cov) < g[i].mass + g[j].mass;
        }
    CHECK(with_loss > 0);
    CHECK(field_counts > 100);
}

TEST_CASE("simplify: the field error F against a numerical integral", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Pairs of anisotropic Gaussians (axes within 4x of each other), some overlapping, some apart,
    // opacities from faint to opaque (so the merged opacity is capped for some): F against the
    // midpoint rule on a grid of step <= a third of the smallest axis over +-7 of the largest,
    // where the rule's error is far below 1e-9 relatively.
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> nrm(0.0, 1.0);
    int capped = 0;
    for (int trial = 0; trial < 6; ++trial) {
        GaussianCloud c(2, 0);
        for (std::size_t i = 0; i < 2; ++i) {
            for (int a = 0; a < 3; ++a) {
                c.means[3 * i + a] = float((trial % 3) * 0.6 * nrm(rng) * (i == 1));
                c.scales[3 * i + a] = float(0.5 + 1.5 * u(rng));
            }
            Eigen::Vector4d q(nrm(rng), nrm(rng), nrm(rng), nrm(rng));
            q.normalize();
            for (int a = 0; a < 4; ++a) c.rotations[4 * i + a] = float(q[a]);
            c.opacities[i] = float(trial < 3 ? 0.1 + 0.3 * u(rng) : 0.7 + 0.3 * u(rng));
        }
        const MergeInput a = MergeInput::of(c, 0), b = MergeInput::of(c, 1);
        const PairTerms t = pair_terms(a, b, c.sh.data(), c.sh.data() + 3, 3);
        const double om = merged_opacity(a, b, covariance_area(t.cov));
        capped += om == 1.0;
        const double fast = field_error(a, b, t, om);
        // The reference: the fields written out and integrated.
        const auto [pa, pb] = pair_weights(a, b);
        const Eigen::Vector3d mm = pa * a.mean + pb * b.mean;
        const Eigen::Matrix3d floor = (1e-6 * t.cov.trace() / 3.0) * Eigen::Matrix3d::Identity();
        const Eigen::Matrix3d ia = (a.cov + floor).inverse(), ib = (b.cov + floor).inverse(), im = (t.cov + floor).inverse();
        double lo = 1e300, step = 1e300;
        Eigen::Vector3d box_lo = Eigen::Vector3d::Constant(1e300), box_hi = Eigen::Vector3d::Constant(-1e300);
        for (const Eigen::Matrix3d* s : {&a.cov, &b.cov, &t.cov}) {
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> e(*s);
            lo = std::min(lo, std::sqrt(e.eigenvalues()[0]));
            step = std::min(step, std::sqrt(e.eigenvalues()[0]) / 3.0);
        }
        for (const Eigen::Vector3d* m : {&a.mean, &b.mean}) {
            box_lo = box_lo.cwiseMin(*m - Eigen::Vector3d::Constant(7.0 * 2.0 * std::sqrt(3.0)));
            box_hi = box_hi.cwiseMax(*m + Eigen::Vector3d::Constant(7.0 * 2.0 * std::sqrt(3.0)));
        }
        // Axes are at most 2 (so 7 x 2 sqrt(3) covers +-7 sigma of every member and the merge,
        // whose axes are at most sqrt(4 + |d|^2 / 4) here, within the box widened by the means).
        box_lo -= Eigen::Vector3d::Constant(2.0);
        box_hi += Eigen::Vector3d::Constant(2.0);
        const Eigen::Vector3i cells = ((box_hi - box_lo) / step).array().ceil().cast<int>();
        const Eigen::Vector3d h = (box_hi - box_lo).cwiseQuotient(cells.cast<double>());
        double sum = 0.0;
        for (int x = 0; x < cells[0]; ++x)
            for (int y = 0; y < cells[1]; ++y)
                for (int z = 0; z < cells[2]; ++z) {
                    const Eigen::Vector3d p = box_lo + Eigen::Vector3d(x + 0.5, y + 0.5, z + 0.5).cwiseProduct(h);
                    const Eigen::Vector3d da = p - a.mean, db = p - b.mean, dm = p - mm;
                    const double v = a.opacity * std::exp(-0.5 * da.dot(ia * da)) + b.opacity * std::exp(-0.5 * db.dot(ib * db)) -
                                     om * std::exp(-0.5 * dm.dot(im * dm));
                    sum += v * v;
                }
        const double ref = sum * h.prod();
        INFO("trial " << trial << ": F " << fast << ", integral " << ref << " (" << cells.transpose() << " cells)");
        CHECK(ref > 0.0);
        CHECK(fast == Approx(ref).epsilon(1e-6));
    }
    CHECK(capped > 0);
}

TEST_CASE("simplify: the field term's weight is scale-free and falls as sqrt(target / size)", "[simplify]") {
    using namespace avsplat::reduce_detail;
    const GaussianCloud c = stiff_clustered(2000, 31, 30, 6);
    GaussianCloud big = c;  // the same scene 1000 times larger
    for (float& x : big.means) x *= 1000.f;
    for (float& x : big.scales) x *= 1000.f;
    std::vector<MergeInput> g(c.size()), gb(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) g[i] = MergeInput::of(c, i), gb[i] = MergeInput::of(big, i);
    // The weight: kFieldWeight sqrt(target / size) over the median field energy.
    std::vector<double> e(g.size());
    for (std::size_t i = 0; i < g.size(); ++i) {
        const Eigen::Matrix3d s = g[i].cov + (1e-6 * g[i].cov.trace() / 3.0) * Eigen::Matrix3d::Identity();
        e[i] = std::pow(simplify_test::kPi, 1.5) * g[i].opacity * g[i].opacity * std::sqrt(s.determinant());
    }
    std::sort(e.begin(), e.end());
    const double unit = kFieldWeight / e[e.size() / 2];
    const double full = 0.25 * unit;  // at 1/16
    CHECK(field_weight(g, 250) == Approx(std::sqrt(0.125) * unit).epsilon(1e-9));  // 1/8
    CHECK(field_weight(g, 125) == Approx(full).epsilon(1e-9));                       // 1/16
    CHECK(field_weight(g, 20) == Approx(0.1 * unit).epsilon(1e-9));                  // 1/100
    CHECK(field_weight(g, 1999) == Approx(std::sqrt(0.9995) * unit).epsilon(1e-9));
    CHECK(field_weight(g, 2000) == 0.0);  // nothing to merge
    CHECK(field_weight(g, 3000) == 0.0);
    CHECK(field_weight(g, 0) == 0.0);
    // The cost with the weight of each scene is the same for both: F scales as length^3, the
    // median energy too.
    const double wb = field_weight(gb, 125);
    CHECK(wb == Approx(full * 1e-9).epsilon(1e-5));
    int field_counts = 0;
    for (std::size_t i = 0; i + 7 < c.size(); ++i) {
        const std::size_t j = i + 7;
        const double cost = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12, full);
        const double cost_big = merge_cost(gb[i], gb[j], &big.sh[12 * i], &big.sh[12 * j], 12, wb);
        INFO("pair " << i << ", " << j);
        // (The means are scaled in float: costs below 1e-6 are rounding.)
        CHECK(cost_big == Approx(cost).epsilon(1e-5).margin(1e-6));
        field_counts += cost - merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12) >= 0.1 * cost;
    }
    CHECK(field_counts > 20);
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
    // The field term on these pairs: never NaN, never negative (as weighed at 1/16).
    const double fw = field_weight(g, n / 16);
    REQUIRE(fw > 0.0);
    std::size_t lossy = 0, lossy_tight = 0, with_field = 0;
    for (std::size_t i = 0; i + 1 < n; ++i)
        for (std::size_t j : {i + 1, i + 2}) {
            if (j >= n) continue;
            const double cost = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            const double lb = merge_cost_lower_bound(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12);
            INFO("pair " << i << ", " << j << ": cost " << cost << ", bound " << lb);
            REQUIRE(lb >= 0.0);
            REQUIRE(lb <= cost);
            const double cost_f = merge_cost(g[i], g[j], &c.sh[12 * i], &c.sh[12 * j], 12, fw);
            REQUIRE(!std::isnan(cost_f));
            REQUIRE(cost_f >= cost);
            with_field += cost_f > cost;
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
    CHECK(with_field > 1000);
    INFO("lossy " << lossy << ", tight " << lossy_tight);
    CHECK(double(lossy_tight) >= 0.5 * double(lossy));
}

TEST_CASE("simplify: cover and exposure against Eigen's inverse and a hand-computed case", "[simplify]") {
    using namespace avsplat::reduce_detail;
    // Hand-computed: two unit spheres (covariance I each) 2 apart, the neighbour of opacity 0.5:
    // 0.5 exp(-d^T (2 I)^-1 d / 2) = 0.5 exp(-1), up to the floor 1e-6 tr(2 I) / 3 = 2e-6.
    GaussianCloud two(2, 0);
    for (int a = 0; a < 3; ++a) two.scales[a] = two.scales[3 + a] = 1.f;
    two.rotations = {1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f};
    two.means = {0.f, 0.f, 0.f, 2.f, 0.f, 0.f};
    two.opacities = {1.f, 0.5f};
    const MergeInput p = MergeInput::of(two, 0), q = MergeInput::of(two, 1);
    CHECK(cover(p, q) == Approx(0.5 * std::exp(-4.0 / (2.0 * (2.0 + 2e-6)))).epsilon(1e-12));
    CHECK(cover(q, p) == Approx(2.0 * cover(p, q)).epsilon(1e-12));  // symmetric but for the opacity
    // Exposure of both from lists naming each other: exp(-kCoverWeight c / 2).
    const std::vector<MergeInput> gp = {p, q};
    const std::uint32_t nb2[] = {1, 0};
    const std::vector<double> h2 = exposure(gp, nb2, 1);
    CHECK(h2[0] == Approx(std::exp(-0.5 * kCoverWeight * cover(p, q))).epsilon(1e-14));
    CHECK(h2[1] == Approx(std::exp(-0.5 * kCoverWeight * cover(q, p))).epsilon(1e-14));

    // Random flat, needle and round Gaussians: cover() from the adjugate against Eigen's inverse
    // (rows i and i + 20 are in the same of the 20 clusters).
    const GaussianCloud c = stiff_clustered(600, 41, 20, 6);
    std::vector<MergeInput> g(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) g[i] = MergeInput::of(c, i);
    std::size_t covered = 0;
    for (std::size_t i = 0; i + 40 < c.size(); ++i)
        for (std::size_t j : {i + 1, i + 20, i + 40}) {
            Eigen::Matrix3d s = g[i].cov + g[j].cov;
            s += (1e-6 * s.trace() / 3.0 + 1e-300) * Eigen::Matrix3d::Identity();
            const Eigen::Vector3d d = g[i].mean - g[j].mean;
            const double ref = s.determinant() > 0.0 ? g[j].opacity * std::exp(-0.5 * d.dot(s.inverse() * d)) : 0.0;
            INFO("pair " << i << ", " << j);
            CHECK(cover(g[i], g[j]) == Approx(ref).epsilon(1e-7).margin(1e-12));
            covered += ref > 1e-3;
        }
    CHECK(covered > 50);  // the pairs do cover each other (a test of exp(-inf) = 0 alone would pass)
    // exposure: the sum over each list (kNone skipped), in list order.
    const std::size_t k = 5, n = c.size();
    std::vector<std::uint32_t> nb(n * k);
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t t = 0; t < k; ++t) nb[i * k + t] = t == 2 ? kNone : std::uint32_t((i + 20 * (t + 1)) % n);
    const std::vector<double> h = exposure(g, nb.data(), k);
    REQUIRE(h.size() == n);
    std::size_t hidden = 0;
    for (std::size_t i = 0; i < n; ++i) {
        double sum = 0.0;
        for (std::size_t t = 0; t < k; ++t)
            if (nb[i * k + t] != kNone) sum += cover(g[i], g[nb[i * k + t]]);
        CHECK(h[i] == std::exp(-0.5 * kCoverWeight * sum));
        CHECK(h[i] > 0.0);
        CHECK(h[i] <= 1.0);
        hidden += h[i] < 0.9;
    }
    CHECK(hidden > 10);
}
