// The maths of merging two Gaussians (simplify's Merge method; avsplat/reduce/simplify.h gives
// the formulas and why): mass, moment match, merged opacity and the merge cost. All in double.
// The cost's lower bound, which orders the candidates of a round, is in merge_cost_bound.h.
#pragma once

#include "avsplat/core/gaussians.h"

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <tuple>

namespace avsplat::reduce_detail {

/// SH degree-0 constant 1 / (2 sqrt(pi)).
constexpr double kShC0 = 0.28209479177387814;
/// 4 pi: the surface area of the unit sphere.
constexpr double kFourPi = 12.566370614359172954;

/// Surface area of the ellipsoid with semi-axes a, b, c (Knud Thomsen, p = 1.6075; relative
/// error below 1.1 %, exact for spheres). Scales the axes by the largest first, so scales of
/// 1e-30 or 1e30 neither underflow nor overflow on the way.
inline double ellipsoid_area(double a, double b, double c) {
    constexpr double p = 1.6075;
    const double m = std::max({a, b, c});
    if (!(m > 0.0)) return 0.0;
    // The largest axis gives (m / m)^p = 1 exactly: no call for it.
    auto power = [m](double s) { return s == m ? 1.0 : std::pow(s / m, p); };
    const double x = power(a), y = power(b), z = power(c);
    constexpr double pi = 3.14159265358979323846;
    return 4.0 * pi * m * m * std::pow((x * y + x * z + y * z) / 3.0, 1.0 / p);
}

/// What the merge reads of one Gaussian, in double.
struct MergeInput {
    Eigen::Vector3d mean;
    Eigen::Matrix3d cov;
    double opacity = 0.0;
    double area = 0.0;  ///< ellipsoid_area of the scales
    double mass = 0.0;  ///< opacity * area
    /// Invariants of cov (trace, sum of principal 2x2 minors, determinant): det(cov + f I) =
    /// f^3 + f^2 tr + f e2 + det without forming the matrix.
    double tr = 0.0, e2 = 0.0, det = 0.0;

    void set_invariants() {
        const Eigen::Matrix3d& c = cov;
        tr = c(0, 0) + c(1, 1) + c(2, 2);
        e2 = c(0, 0) * c(1, 1) - c(0, 1) * c(0, 1) + c(0, 0) * c(2, 2) - c(0, 2) * c(0, 2) + c(1, 1) * c(2, 2) -
             c(1, 2) * c(1, 2);
        det = c.determinant();
    }

    static MergeInput of(const GaussianCloud& c, std::size_t i) {
        MergeInput g;
        g.mean = c.mean(i).cast<double>();
        g.cov = c.covariance(i);
        g.opacity = double(c.opacities[i]);
        g.area = ellipsoid_area(double(c.scales[3 * i]), double(c.scales[3 * i + 1]), double(c.scales[3 * i + 2]));
        g.mass = g.opacity * g.area;
        g.set_invariants();
        return g;
    }
};

/// Weights (pi_i, pi_j) of a pair: by mass; pairs without mass (zero area) by opacity; pairs
/// without either equally.
inline std::pair<double, double> pair_weights(const MergeInput& a, const MergeInput& b) {
    double wa = a.mass, wb = b.mass;
    if (!(wa + wb > 0.0) || !std::isfinite(wa + wb)) wa = a.opacity, wb = b.opacity;
    if (!(wa + wb > 0.0)) return {0.5, 0.5};
    const double pa = wa / (wa + wb);
    return {pa, 1.0 - pa};
}

/// Moment-matched mean and covariance of a pair with weights (pa, pb).
inline void moment_match(const MergeInput& a, const MergeInput& b, double pa, double pb,
                         Eigen::Vector3d& mean, Eigen::Matrix3d& cov) {
    mean = pa * a.mean + pb * b.mean;
    const Eigen::Vector3d d = a.mean - b.mean;
    // sum_k p_k d_k d_k^T = pa pb d d^T for two members.
    cov = pa * a.cov + pb * b.cov + (pa * pb) * (d * d.transpose());
}

/// Opacity of the merged Gaussian of surface area `area`: the ink W = mass_a + mass_b spread
/// over the merged area, capped at 1 (splat-transform's rule). Without area (points), the larger
/// opacity.
inline double merged_opacity(const MergeInput& a, const MergeInput& b, double area) {
    if (!(area > 0.0)) return std::max(a.opacity, b.opacity);
    return std::clamp((a.mass + b.mass) / area, 0.0, 1.0);
}

/// Surface area of the Gaussian with covariance `cov` (its semi-axes are the square roots of the
/// eigenvalues).
inline double covariance_area(const Eigen::Matrix3d& cov) {
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
    eig.computeDirect(cov, Eigen::EigenvaluesOnly);
    const Eigen::Vector3d ev = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
    return ellipsoid_area(ev[0], ev[1], ev[2]);
}

/// Eigenvalues of the symmetric 3x3 matrix `c` by the trigonometric closed form (Smith 1961), as
/// accurate as Eigen's computeDirect for the covariances here and about twice as fast.
inline Eigen::Vector3d symmetric_eigenvalues(const Eigen::Matrix3d& c) {
    const double p1 = c(0, 1) * c(0, 1) + c(0, 2) * c(0, 2) + c(1, 2) * c(1, 2);
    const double q = (c(0, 0) + c(1, 1) + c(2, 2)) / 3.0;
    const double a = c(0, 0) - q, b = c(1, 1) - q, d = c(2, 2) - q;
    const double p2 = a * a + b * b + d * d + 2.0 * p1;
    if (!(p2 > 1e-30 * q * q)) return Eigen::Vector3d(c(0, 0), c(1, 1), c(2, 2));  // a multiple of I
    const double p = std::sqrt(p2 / 6.0);
    // det(c - q I) / (2 p^3), in [-1, 1] up to rounding.
    const double detb = a * (b * d - c(1, 2) * c(1, 2)) - c(0, 1) * (c(0, 1) * d - c(1, 2) * c(0, 2)) +
                        c(0, 2) * (c(0, 1) * c(1, 2) - b * c(0, 2));
    const double r = std::clamp(detb / (2.0 * p * p * p), -1.0, 1.0);
    const double phi = std::acos(r) / 3.0;
    constexpr double kTwoThirdsPi = 2.0943951023931954923;
    const double e1 = q + 2.0 * p * std::cos(phi);
    const double e3 = q + 2.0 * p * std::cos(phi + kTwoThirdsPi);
    return Eigen::Vector3d(e1, 3.0 * q - e1 - e3, e3);
}

/// ellipsoid_area in float (powf is several times faster than pow): the merge cost's area, where
/// a relative error of 1e-7 does not matter.
inline double ellipsoid_area_f(double a, double b, double c) {
    constexpr float p = 1.6075f;
    const double m = std::max({a, b, c});
    if (!(m > 0.0)) return 0.0;
    auto power = [m](double s) { return s == m ? 1.0f : std::pow(float(s / m), p); };  // as ellipsoid_area
    const float x = power(a), y = power(b), z = power(c);
    constexpr double pi = 3.14159265358979323846;
    return 4.0 * pi * m * m * double(std::pow((x * y + x * z + y * z) / 3.0f, 1.0f / p));
}

/// Weight of the colour term against the geometric one (see merge_cost).
constexpr double kColourWeight = 30.0;
/// Weight of the degree-0 (DC) coefficients in the colour term, the higher bands' being 1: the DC
/// difference shows from every direction (chosen as in docs/design/reduction.md).
constexpr double kDcWeight = 2.0;
/// Weight of the lost-ink term L against the geometric one (see merge_cost; chosen as in
/// docs/design/reduction.md).
constexpr double kLossWeight = 2.0;
/// Relative floor of the covariances in the geometric term: delta^2 = kFloor tr(Sigma) / 3.
constexpr double kFloor = 1e-4;

/// Squared distance of two rows of k3 SH coefficients, in double: four partial sums (coefficient
/// c goes to sum c mod 4), added as (s0 + s1) + (s2 + s3). Four accumulators in registers, which
/// the compiler can keep in one vector: one chain of 48 dependent additions (degree 3), or the
/// sums in an array indexed by c & 3 (a store and a reload per coefficient), was the slowest part
/// of the merge cost.
inline double sh_distance2(const float* a, const float* b, std::size_t k3) {
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    std::size_t c = 0;
    for (; c + 4 <= k3; c += 4) {
        const double d0 = double(a[c]) - double(b[c]), d1 = double(a[c + 1]) - double(b[c + 1]);
        const double d2 = double(a[c + 2]) - double(b[c + 2]), d3 = double(a[c + 3]) - double(b[c + 3]);
        s0 += d0 * d0;
        s1 += d1 * d1;
        s2 += d2 * d2;
        s3 += d3 * d3;
    }
    if (c < k3) {
        const double d = double(a[c]) - double(b[c]);
        s0 += d * d;
    }
    if (c + 1 < k3) {
        const double d = double(a[c + 1]) - double(b[c + 1]);
        s1 += d * d;
    }
    if (c + 2 < k3) {
        const double d = double(a[c + 2]) - double(b[c + 2]);
        s2 += d * d;
    }
    return (s0 + s1) + (s2 + s3);
}

/// det(Sigma + f I) from the invariants of Sigma (MergeInput::set_invariants): a cubic in f with
/// positive coefficients, so no cancellation.
inline double floored_determinant(double f, double tr, double e2, double det) {
    return ((f + tr) * f + e2) * f + det;
}

/// What merge_cost and merge_cost_lower_bound share: the weights, the merged covariance and its
/// invariants, the floored determinants and the colour term, computed once the same way for both.
struct PairTerms {
    double pa = 0.0, pb = 0.0;
    Eigen::Matrix3d cov;
    double tr = 0.0, e2 = 0.0, det = 0.0;  ///< invariants of cov (MergeInput::set_invariants)
    double fd = 0.0, fda = 0.0, fdb = 0.0;  ///< det(S), det(S_a), det(S_b) with the floor
    double colour = 0.0;                    ///< C, weighted (the DC by kDcWeight)
};

inline PairTerms pair_terms(const MergeInput& a, const MergeInput& b, const float* sh_a, const float* sh_b,
                            std::size_t k3) {
    PairTerms t;
    std::tie(t.pa, t.pb) = pair_weights(a, b);
    const double pa = t.pa, pb = t.pb;
    const Eigen::Vector3d d = a.mean - b.mean;
    t.cov = pa * a.cov + pb * b.cov + (pa * pb) * (d * d.transpose());
    const Eigen::Matrix3d& cov = t.cov;
    const double tr = cov(0, 0) + cov(1, 1) + cov(2, 2);
    const double e2 = cov(0, 0) * cov(1, 1) - cov(0, 1) * cov(0, 1) + cov(0, 0) * cov(2, 2) - cov(0, 2) * cov(0, 2) +
                      cov(1, 1) * cov(2, 2) - cov(1, 2) * cov(1, 2);
    t.tr = tr;
    t.e2 = e2;
    t.det = cov.determinant();
    // The floor relative to the merged size (see merge_cost).
    const double f = kFloor * tr / 3.0 + 1e-300;
    t.fd = floored_determinant(f, tr, e2, t.det);
    t.fda = floored_determinant(f, a.tr, a.e2, a.det);
    t.fdb = floored_determinant(f, b.tr, b.e2, b.det);
    const double rest = k3 > 3 ? sh_distance2(sh_a + 3, sh_b + 3, k3 - 3) : 0.0;
    t.colour = kColourWeight * pa * pb * kShC0 * kShC0 * (kDcWeight * sh_distance2(sh_a, sh_b, 3) + rest);
    return t;
}

/// The merge cost G + 2 L + C of the file comment of simplify.h. `sh_a`, `sh_b`: the k3 SH
/// coefficients of each. The determinants come from the invariants (det(S + f I) is a cubic in f
/// with positive coefficients, so no cancellation); the merged area's eigenvalues are needed only
/// when the area could be below the ink W: Thomsen's area is a power mean (p >= 0) of ab, ac, bc,
/// so it is at least their geometric mean, 4 pi det^(1/3), and L = 0 when that is >= W.
inline double merge_cost(const MergeInput& a, const MergeInput& b, const float* sh_a, const float* sh_b,
                         std::size_t k3) {
    const PairTerms t = pair_terms(a, b, sh_a, sh_b, k3);
    // Runnalls' bound on the KL divergence of the pair from its moment match, per unit weight,
    // on covariances with a floor relative to the merged size (so flat and needle Gaussians, whose
    // determinant is 0, stay finite, and the cost does not change with the scene's scale).
    const double g = std::max(0.0, 0.5 * (std::log(t.fd) - t.pa * std::log(t.fda) - t.pb * std::log(t.fdb)));
    const double w = a.mass + b.mass;
    double l = 0.0;
    if (w > 0.0 && !(kFourPi * std::cbrt(std::max(t.det, 0.0)) >= w)) {
        // The merged surface area, from the eigenvalues.
        const Eigen::Vector3d ev = symmetric_eigenvalues(t.cov).cwiseMax(0.0).cwiseSqrt();
        const double area = ellipsoid_area_f(ev[0], ev[1], ev[2]);
        if (area > 0.0) l = std::max(0.0, 1.0 - std::min(1.0, w / area) * area / w);
    }
    const double cost = g + kLossWeight * l + t.colour;
    return std::isfinite(cost) ? cost : HUGE_VAL;
}

/// Writes the merge of a and b (rows ia, ib of `in`) into row o of `out` (same SH degree,
/// confidence and extras as `in`).
inline void merge_pair(const GaussianCloud& in, std::size_t ia, std::size_t ib, const MergeInput& a,
                       const MergeInput& b, GaussianCloud& out, std::size_t o) {
    const auto [pa, pb] = pair_weights(a, b);
    Eigen::Vector3d mean;
    Eigen::Matrix3d cov;
    moment_match(a, b, pa, pb, mean, cov);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    Eigen::Matrix3d r = eig.eigenvectors();
    if (r.determinant() < 0.0) r.col(0) = -r.col(0);
    Eigen::Quaterniond q(r);
    q.normalize();
    if (q.w() < 0.0) q.coeffs() = -q.coeffs();
    const Eigen::Vector3d s = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
    for (int k = 0; k < 3; ++k) {
        out.means[3 * o + k] = float(mean[k]);
        out.scales[3 * o + k] = float(s[k]);
    }
    out.rotations[4 * o] = float(q.w());
    out.rotations[4 * o + 1] = float(q.x());
    out.rotations[4 * o + 2] = float(q.y());
    out.rotations[4 * o + 3] = float(q.z());
    out.opacities[o] = float(merged_opacity(a, b, ellipsoid_area(s[0], s[1], s[2])));
    const std::size_t k3 = std::size_t(in.sh_coeffs()) * 3;
    for (std::size_t c = 0; c < k3; ++c)
        out.sh[k3 * o + c] = float(pa * double(in.sh[k3 * ia + c]) + pb * double(in.sh[k3 * ib + c]));
    if (in.has_confidence())
        out.confidence[o] = float(pa * double(in.confidence[ia]) + pb * double(in.confidence[ib]));
    for (std::size_t e = 0; e < in.extras.size(); ++e)
        out.extras[e].values[o] =
            float(pa * double(in.extras[e].values[ia]) + pb * double(in.extras[e].values[ib]));
}

}  // namespace avsplat::reduce_detail
