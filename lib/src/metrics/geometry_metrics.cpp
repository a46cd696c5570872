#include "avsplat/metrics/geometry_metrics.h"

#include "common/kdtree.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

using detail::KdTree;

void check_points(const char* fn, const char* field, const float* p, std::size_t n) {
    if (n > 0 && p == nullptr)
        throw std::invalid_argument(std::string(fn) + ": " + field + " is null");
    for (std::size_t i = 0; i < 3 * n; ++i)
        if (!std::isfinite(p[i]))
            throw std::invalid_argument(std::string(fn) + ": " + field + "[" +
                                        std::to_string(i / 3) + "] is not finite");
}

// Nearest-neighbour distance from each source point to the target set (target non-empty).
std::vector<double> nearest_distances(const float* source, std::size_t n_source,
                                      const KdTree& target) {
    std::vector<double> d(n_source);
#pragma omp parallel for schedule(static)
    for (std::int64_t i = 0; i < static_cast<std::int64_t>(n_source); ++i) {
        std::uint32_t j;
        double d2;
        target.knn(source + 3 * i, 1, &j, &d2);
        d[i] = std::sqrt(d2);
    }
    return d;
}

// Sums in a fixed order, so the result does not depend on the thread count.
double mean(const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
}

}  // namespace

std::vector<std::size_t> remove_statistical_outliers(const float* points, std::size_t n,
                                                     int nb_neighbors, double std_ratio) {
    const char* fn = "remove_statistical_outliers";
    if (nb_neighbors < 1) throw std::invalid_argument(std::string(fn) + ": nb_neighbors must be >= 1");
    if (!(std_ratio >= 0.0) || !std::isfinite(std_ratio))
        throw std::invalid_argument(std::string(fn) + ": std_ratio must be finite and >= 0");
    check_points(fn, "points", points, n);
    std::vector<std::size_t> kept;
    if (n == 0) return kept;
    const KdTree tree(points, n, fn);
    const std::size_t k = std::min<std::size_t>(nb_neighbors, n);
    std::vector<double> avg(n);
#pragma omp parallel
    {
        std::vector<std::uint32_t> idx(k);
        std::vector<double> d2(k);
#pragma omp for schedule(static)
        for (std::int64_t i = 0; i < static_cast<std::int64_t>(n); ++i) {
            const std::size_t found = tree.knn(points + 3 * i, k, idx.data(), d2.data());
            double s = 0.0;
            for (std::size_t t = 0; t < found; ++t) s += std::sqrt(d2[t]);
            avg[i] = s / static_cast<double>(found);
        }
    }
    if (n == 1) return {0};
    const double mu = mean(avg);
    double ss = 0.0;  // two-pass variance (numerics policy)
    for (double a : avg) ss += (a - mu) * (a - mu);
    const double threshold = mu + std_ratio * std::sqrt(ss / static_cast<double>(n - 1));
    for (std::size_t i = 0; i < n; ++i)
        if (avg[i] <= threshold) kept.push_back(i);
    return kept;
}

std::vector<double> compute_point_cloud_distance(const float* source, std::size_t n_source,
                                                 const float* target, std::size_t n_target) {
    const char* fn = "compute_point_cloud_distance";
    check_points(fn, "source", source, n_source);
    check_points(fn, "target", target, n_target);
    if (n_source == 0) return {};
    if (n_target == 0) throw std::invalid_argument(std::string(fn) + ": target is empty");
    const KdTree tree(target, n_target, fn);
    return nearest_distances(source, n_source, tree);
}

AccuracyCompleteness accuracy_completeness(const float* pred, std::size_t n_pred,
                                           const float* gt, std::size_t n_gt, double threshold) {
    const char* fn = "accuracy_completeness";
    if (!(threshold > 0.0) || !std::isfinite(threshold))
        throw std::invalid_argument(std::string(fn) + ": threshold must be finite and > 0");
    if (n_pred == 0) throw std::invalid_argument(std::string(fn) + ": pred is empty");
    if (n_gt == 0) throw std::invalid_argument(std::string(fn) + ": gt is empty");
    check_points(fn, "pred", pred, n_pred);
    check_points(fn, "gt", gt, n_gt);
    const std::vector<double> to_gt = nearest_distances(pred, n_pred, KdTree(gt, n_gt, fn));
    const std::vector<double> to_pred = nearest_distances(gt, n_gt, KdTree(pred, n_pred, fn));
    AccuracyCompleteness r;
    r.threshold = threshold;
    r.accuracy = mean(to_gt);
    r.completeness = mean(to_pred);
    r.chamfer = 0.5 * (r.accuracy + r.completeness);
    auto fraction_below = [threshold](const std::vector<double>& d) {
        std::size_t c = 0;
        for (double x : d) c += x < threshold;
        return static_cast<double>(c) / static_cast<double>(d.size());
    };
    r.precision = fraction_below(to_gt);
    r.recall = fraction_below(to_pred);
    r.fscore = r.precision + r.recall > 0.0 ? 2.0 * r.precision * r.recall / (r.precision + r.recall) : 0.0;
    return r;
}

double chamfer_distance(const float* a, std::size_t n_a, const float* b, std::size_t n_b) {
    const char* fn = "chamfer_distance";
    if (n_a == 0 || n_b == 0) throw std::invalid_argument(std::string(fn) + ": a point set is empty");
    check_points(fn, "a", a, n_a);
    check_points(fn, "b", b, n_b);
    const double ab = mean(nearest_distances(a, n_a, KdTree(b, n_b, fn)));
    const double ba = mean(nearest_distances(b, n_b, KdTree(a, n_a, fn)));
    return 0.5 * (ab + ba);
}

}  // namespace avsplat
