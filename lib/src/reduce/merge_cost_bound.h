// A lower bound of simplify's merge cost (moment_merge.h) without a logarithm, a cube root or an
// eigenvalue: the Merge rounds (simplify_merge.cpp) order every candidate pair by it and price the
// full cost only for the pairs the greedy scan reaches.
#pragma once

#include "reduce/moment_merge.h"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

namespace avsplat::reduce_detail {

/// The part of ln x that log_series_below leaves out, at most: 2 s^9 / (9 (1 - s^2)) at s = 1/3.
constexpr double kLogSeriesRest = 1.2703e-5;

/// A lower bound of ln x for a normal x > 0 (finite, not subnormal), within kLogSeriesRest of it
/// (rounding aside), without a call into libm: x = m 2^e with m in [1, 2) from the bits, and
/// ln m = 2 (s + s^3 / 3 + s^5 / 5 + s^7 / 7 + ...) with s = (m - 1) / (m + 1) in [0, 1/3): every
/// term is >= 0, so the series cut after s^7 is below ln m, and the rest is below
/// 2 s^9 / (9 (1 - s^2)) <= kLogSeriesRest.
inline double log_series_below(double x) {
    std::uint64_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    const int e = int(bits >> 52) - 1023;
    bits = (bits & ((std::uint64_t(1) << 52) - 1)) | (std::uint64_t(1023) << 52);
    double m;
    std::memcpy(&m, &bits, sizeof m);
    const double s = (m - 1.0) / (m + 1.0), s2 = s * s;
    constexpr double kLn2 = 0.69314718055994530942;
    return double(e) * kLn2 + 2.0 * s * (1.0 + s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0))));
}

/// Whether x is normal and > 0 (finite, not 0 or subnormal, not NaN): log_series_below's domain.
inline bool positive_normal(double x) {
    return x >= std::numeric_limits<double>::min() && x <= std::numeric_limits<double>::max();
}

/// A lower bound of merge_cost (as computed, rounding included) without a logarithm, a cube root
/// or an eigenvalue: the rounds price every candidate with it and call merge_cost only for the
/// pairs the greedy scan reaches with both ends free (the tighter the bound, the fewer). G: the
/// three logarithms by log_series_below, raised by kLogSeriesRest for the two G subtracts (an
/// upper bound of those), so the bound is within kLogSeriesRest of G (pi_a + pi_b = 1); 1e-11
/// covers the rounding of merge_cost's logarithms (|ln| <= 745 in double, so each is off by less
/// than 2e-13) and of the bound. Where a determinant is 0, subnormal or not finite (stiff
/// scales), G >= ln(x) / 2 with x = det S / (pi_a det S_a + pi_b det S_b) (Jensen: the log is
/// concave; ln x by the series too, for x >= 1), and G >= 0. L: see below; C is merge_cost's own
/// term. (Jensen's bound everywhere,
/// used before, was below G by 0.37 on average over the pairs a round priced, pairs of unequal
/// sizes whose det S_a and det S_b are far apart, and the scan priced 2.4 candidates per merge;
/// with the series, 1.2 in the first round (held-out cloud of the reduction report, 1/2).)
inline double merge_cost_lower_bound(const MergeInput& a, const MergeInput& b, const float* sh_a,
                                     const float* sh_b, std::size_t k3) {
    const PairTerms t = pair_terms(a, b, sh_a, sh_b, k3);
    double g = 0.0;
    if (positive_normal(t.fd) && positive_normal(t.fda) && positive_normal(t.fdb)) {
        g = 0.5 * (log_series_below(t.fd) - t.pa * log_series_below(t.fda) - t.pb * log_series_below(t.fdb) -
                   kLogSeriesRest) -
            1e-11;
        g = g > 0.0 ? g : 0.0;
    } else {
        const double x = t.fd / (t.pa * t.fda + t.pb * t.fdb);
        if (x >= 1.0 && x <= std::numeric_limits<double>::max()) g = std::max(0.0, 0.5 * log_series_below(x) - 1e-11);
    }
    // L: Thomsen's area is a power mean (p = 1.6075 <= 2) of ab, ac, bc, so at most their
    // quadratic mean 4 pi sqrt(e2 / 3) (e2 = a^2 b^2 + a^2 c^2 + b^2 c^2, the merged covariance's
    // invariant); L >= 1 - that / W. Only where merge_cost surely computes L from its area:
    // e2 >= 1e-6 tr^2 puts the second eigenvalue far above its rounding error (merge_cost sets
    // L = 0 for an area of 0, a merged needle or point), and keeps sqrt(e2 / 3) >= 5.8e-4 tr far
    // above the rounding noise of merge_cost's shortcut 4 pi cbrt(det) >= W (det is off by at
    // most ~4e-15 tr^3, its cube root by 1.6e-5 tr; elsewhere det^(1/3), the geometric mean, is
    // below the quadratic mean by more than that). The margins: e2's rounding (below 1e-14 tr^2,
    // relative 1e-4 here), merge_cost's float area (relative 1e-6) and the divisions (1e-9).
    double l = 0.0;
    const double w = a.mass + b.mass;
    if (w > 0.0 && t.tr > 0.0 && t.e2 >= 1e-6 * t.tr * t.tr) {
        const double upper = kFourPi * std::sqrt(t.e2 / 3.0) * (1.0 + 1e-4);
        if (upper < w) l = std::max(0.0, 1.0 - upper / w - 1e-9);
    }
    const double lb = g + kLossWeight * l + t.colour;
    return lb >= 0.0 ? lb : 0.0;  // NaN: no bound but 0
}

}  // namespace avsplat::reduce_detail
