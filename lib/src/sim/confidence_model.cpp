// The confidence of a given informativeness (a Gaussian copula on ranks) and Spearman's rho.
#include "sim/prediction_errors.h"
#include "sim/random.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace avsplat::sim {

namespace {

// Ranks 0..n-1 of a (ties get their mean rank).
std::vector<double> mean_ranks(const std::vector<double>& a) {
    const std::size_t n = a.size();
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), std::size_t(0));
    std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) { return a[i] < a[j] || (a[i] == a[j] && i < j); });
    std::vector<double> rank(n);
    for (std::size_t b = 0; b < n;) {
        std::size_t e = b + 1;
        while (e < n && a[order[e]] == a[order[b]]) ++e;
        const double r = 0.5 * double(b + e - 1);
        for (std::size_t k = b; k < e; ++k) rank[order[k]] = r;
        b = e;
    }
    return rank;
}

// Positions 0..n-1 of a in ascending order, ties by index.
std::vector<std::size_t> order_of(const std::vector<double>& a) {
    std::vector<std::size_t> order(a.size());
    std::iota(order.begin(), order.end(), std::size_t(0));
    std::sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) { return a[i] < a[j] || (a[i] == a[j] && i < j); });
    return order;
}

// The standard normal quantile Phi^-1(p), p in (0, 1): Acklam's rational approximation
// (relative error < 1.2e-9), plenty for ranks.
double normal_quantile(double p) {
    static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
                               1.383577518672690e+02, -3.066479806614716e+01, 2.506628277459239e+00};
    static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                               6.680131188771972e+01, -1.328068155288572e+01};
    static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                               -2.549732539343734e+00, 4.374664141464968e+00, 2.938163982698783e+00};
    static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                               3.754408661907416e+00};
    constexpr double lo = 0.02425, hi = 1.0 - lo;
    if (p < lo) {
        const double q = std::sqrt(-2.0 * std::log(p));
        return (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
               ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
    }
    if (p > hi) {
        const double q = std::sqrt(-2.0 * std::log(1.0 - p));
        return -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
               ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
    }
    const double q = p - 0.5, r = q * q;
    return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
           (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0);
}

}  // namespace

double spearman(const std::vector<double>& a, const std::vector<double>& b) {
    const std::size_t n = a.size();
    if (n < 2 || b.size() != n) return std::numeric_limits<double>::quiet_NaN();
    const std::vector<double> ra = mean_ranks(a), rb = mean_ranks(b);
    const double mean = 0.5 * double(n - 1);
    double sab = 0.0, saa = 0.0, sbb = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const double x = ra[i] - mean, y = rb[i] - mean;
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    if (!(saa > 0.0 && sbb > 0.0)) return std::numeric_limits<double>::quiet_NaN();
    return sab / std::sqrt(saa * sbb);
}

std::vector<double> confidence_by_rank(const std::vector<double>& values, const std::vector<double>& score,
                                       const std::vector<double>& noise, double rho) {
    const std::size_t n = values.size();
    // Pearson correlation of a bivariate normal whose Spearman correlation is rho.
    const double r = std::clamp(2.0 * std::sin(kPi * rho / 6.0), -1.0, 1.0);
    const double s = std::sqrt(std::max(0.0, 1.0 - r * r));
    const std::vector<std::size_t> by_score = order_of(score);
    std::vector<double> y(n);
    for (std::size_t k = 0; k < n; ++k) {
        const std::size_t i = by_score[k];
        const double z = normal_quantile((double(k) + 0.5) / double(n));
        y[i] = r * z + s * noise[i];
    }
    std::vector<double> sorted = values;
    std::sort(sorted.begin(), sorted.end());
    const std::vector<std::size_t> by_y = order_of(y);
    std::vector<double> out(n);
    for (std::size_t k = 0; k < n; ++k) out[by_y[k]] = sorted[k];
    return out;
}

}  // namespace avsplat::sim
