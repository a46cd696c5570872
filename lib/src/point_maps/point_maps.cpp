#include "avsplat/point_maps/point_maps.h"
#include "fusion/voxel_weights.h"

#include "avsplat/core/sh.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <nanoflann.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

// nanoflann's dataset interface over an n x 3 float32 array.
struct PointArray {
    const float* data;
    std::size_t n;
    std::size_t kdtree_get_point_count() const { return n; }
    float kdtree_get_pt(std::size_t i, std::size_t dim) const { return data[3 * i + dim]; }
    template <class BBox>
    bool kdtree_get_bbox(BBox&) const { return false; }
};

// A KD-tree over n points. Squared distances are accumulated in double so that they match a
// float64 brute-force reference to rounding of the float32 coordinates. Queries are const and
// may run concurrently.
class KdTree {
public:
    KdTree(const float* points, std::size_t n, const char* fn) : points_{points, n} {
        if (n >= std::numeric_limits<std::uint32_t>::max())
            throw std::invalid_argument(std::string(fn) + ": more than 2^32 - 1 points");
        index_.buildIndex();
    }
    // The min(k, n) nearest points to q, nearest first; returns their count.
    std::size_t knn(const float* q, std::size_t k, std::uint32_t* idx, double* d2) const {
        return index_.knnSearch(q, k, idx, d2);
    }

private:
    using Index = nanoflann::KDTreeSingleIndexAdaptor<
        nanoflann::L2_Simple_Adaptor<float, PointArray, double>, PointArray, 3, std::uint32_t>;
    PointArray points_;
    // Built explicitly in the constructor body, after the size check.
    Index index_{3, points_,
                 nanoflann::KDTreeSingleIndexAdaptorParams(
                     10, nanoflann::KDTreeSingleIndexAdaptorFlags::SkipInitialBuildIndex)};
};

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

std::string pixel_name(const char* field, std::size_t i, const PointMaps& m) {
    const std::size_t per_view = static_cast<std::size_t>(m.height) * m.width;
    return std::string(field) + "[" + std::to_string(i) + "] (view " +
           std::to_string(i / per_view) + ", row " + std::to_string(i % per_view / m.width) +
           ", col " + std::to_string(i % m.width) + ")";
}

void check_options(const PointMapOptions& o) {
    auto fail = [](const std::string& what) {
        throw std::invalid_argument("gaussians_from_point_maps: options." + what);
    };
    if (o.k < 1) fail("k: must be >= 1");
    if (o.normal_neighbors < 3) fail("normal_neighbors: must be >= 3");
    if (!(o.thickness > 0.0 && o.thickness <= 1.0)) fail("thickness: must be in (0, 1]");
    if (!(o.scale_multiplier > 0.0) || !std::isfinite(o.scale_multiplier))
        fail("scale_multiplier: must be finite and > 0");
    if (!(o.max_stretch >= 1.0) || !std::isfinite(o.max_stretch))
        fail("max_stretch: must be finite and >= 1");
    if (!(o.min_scale >= 0.0) || !std::isfinite(o.min_scale))
        fail("min_scale: must be finite and >= 0");
    if (!(o.default_opacity >= 0.0 && o.default_opacity <= 1.0))
        fail("default_opacity: must be in [0, 1]");
}

// A unit vector perpendicular to unit n, chosen from n alone (deterministic).
Eigen::Vector3d any_tangent(const Eigen::Vector3d& n) {
    Eigen::Index axis;
    n.cwiseAbs().minCoeff(&axis);
    return n.cross(Eigen::Vector3d::Unit(axis)).normalized();
}

}  // namespace

GaussianCloud gaussians_from_point_maps(const PointMaps& m, const std::vector<Camera>& cameras,
                                        const PointMapOptions& o) {
    const char* fn = "gaussians_from_point_maps";
    if (m.views < 0 || m.height < 0 || m.width < 0)
        throw std::invalid_argument(std::string(fn) + ": views, height and width must be >= 0");
    check_options(o);
    const std::size_t total = m.pixels();
    if (total > 0 && m.points == nullptr) throw std::invalid_argument(std::string(fn) + ": points is null");
    if (total > 0 && m.colors == nullptr) throw std::invalid_argument(std::string(fn) + ": colors is null");
    const bool use_cameras = !cameras.empty();
    if (use_cameras) {
        if (cameras.size() != static_cast<std::size_t>(m.views))
            throw std::invalid_argument(std::string(fn) + ": cameras has " +
                                        std::to_string(cameras.size()) + " entries for " +
                                        std::to_string(m.views) + " views");
        for (std::size_t s = 0; s < cameras.size(); ++s) {
            try {
                cameras[s].validate();
            } catch (const std::invalid_argument& e) {
                throw std::invalid_argument(std::string(fn) + ": cameras[" + std::to_string(s) + "]: " + e.what());
            }
            if (cameras[s].width != m.width || cameras[s].height != m.height)
                throw std::invalid_argument(
                    std::string(fn) + ": cameras[" + std::to_string(s) + "] is " +
                    std::to_string(cameras[s].width) + " x " + std::to_string(cameras[s].height) +
                    ", the point maps are " + std::to_string(m.width) + " x " + std::to_string(m.height));
        }
    }

    // Gather and check the valid pixels serially, so that the parallel part cannot throw.
    const std::size_t per_view = static_cast<std::size_t>(m.height) * m.width;
    std::vector<std::size_t> source;
    for (std::size_t i = 0; i < total; ++i) {
        if (m.valid && !m.valid[i]) continue;
        auto fail = [&](const char* field, const char* what) {
            throw std::invalid_argument(std::string(fn) + ": " + pixel_name(field, i, m) + " " + what);
        };
        for (int c = 0; c < 3; ++c) {
            if (!std::isfinite(m.points[3 * i + c])) fail("points", "is not finite");
            if (!std::isfinite(m.colors[3 * i + c])) fail("colors", "is not finite");
            if (m.normals && !std::isfinite(m.normals[3 * i + c])) fail("normals", "is not finite");
        }
        if (m.normals && m.normals[3 * i] == 0.f && m.normals[3 * i + 1] == 0.f && m.normals[3 * i + 2] == 0.f)
            fail("normals", "is zero");
        if (m.confidence) {
            const float c = m.confidence[i];
            if (!std::isfinite(c)) fail("confidence", "is not finite");
            if (!fusion_weights::confidence_valid(c, o.confidence_mapping))
                fail("confidence", o.confidence_mapping == ConfidenceMapping::Probability
                                       ? "is outside [0, 1] (confidence mapping Probability)"
                                       : "is negative (confidence mapping Positive)");
        }
        if (use_cameras) {
            const Camera& cam = cameras[i / per_view];
            const Eigen::Vector3d p(m.points[3 * i], m.points[3 * i + 1], m.points[3 * i + 2]);
            const double z = cam.world_to_camera.row(2).head<3>().dot(p) + cam.world_to_camera(2, 3);
            if (!(z > 0.0)) fail("points", "is at or behind its camera (z <= 0)");
        }
        source.push_back(i);
    }
    const std::size_t n = source.size();
    if (n == 0) return GaussianCloud(0, 0);
    if (!use_cameras && n < 2)
        throw std::invalid_argument(std::string(fn) + ": the kNN scale needs at least 2 valid points, got 1");

    std::vector<float> points(3 * n);
    for (std::size_t j = 0; j < n; ++j) std::copy_n(m.points + 3 * source[j], 3, &points[3 * j]);

    const bool pca = o.flat && m.normals == nullptr;
    std::size_t k_query = 0;  // neighbours fetched per point, the point itself included
    if (!use_cameras) k_query = static_cast<std::size_t>(o.k) + 1;
    if (pca) k_query = std::max(k_query, static_cast<std::size_t>(o.normal_neighbors));
    k_query = std::min(k_query, n);
    std::unique_ptr<KdTree> tree;
    if (k_query > 0) tree = std::make_unique<KdTree>(points.data(), n, fn);

    GaussianCloud out(n, 0);
    out.means = points;
    if (m.confidence) out.confidence.resize(n);
    const double c0 = sh::kC0;

#pragma omp parallel
    {
        std::vector<std::uint32_t> idx(k_query);
        std::vector<double> d2(k_query);
#pragma omp for schedule(static)
        for (std::int64_t jj = 0; jj < static_cast<std::int64_t>(n); ++jj) {
            const std::size_t j = static_cast<std::size_t>(jj);
            const std::size_t i = source[j];
            const Eigen::Vector3d p = Eigen::Map<const Eigen::Vector3f>(&points[3 * j]).cast<double>();
            std::size_t found = 0;
            if (tree) found = tree->knn(&points[3 * j], k_query, idx.data(), d2.data());

            double s;
            const Camera* cam = use_cameras ? &cameras[i / per_view] : nullptr;
            if (cam) {
                const double z = cam->world_to_camera.row(2).head<3>().dot(p) + cam->world_to_camera(2, 3);
                s = z / std::sqrt(cam->fx * cam->fy);
            } else {
                // The k nearest other points. When duplicates of the point push it out of the
                // k + 1 found, all of those are at distance 0 and any k of them give s = 0.
                double sum = 0.0;
                std::size_t used = 0;
                for (std::size_t t = 0; t < found && used < static_cast<std::size_t>(o.k); ++t) {
                    if (idx[t] == j) continue;
                    sum += d2[t];
                    ++used;
                }
                s = std::sqrt(sum / static_cast<double>(used));
            }
            s *= o.scale_multiplier;

            Eigen::Vector3d axes(s, s, s);
            Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
            if (o.flat) {
                Eigen::Vector3d nrm;
                if (m.normals) {
                    nrm = Eigen::Map<const Eigen::Vector3f>(&m.normals[3 * i]).cast<double>().normalized();
                } else {
                    const std::size_t used = std::min<std::size_t>(found, o.normal_neighbors);
                    Eigen::Vector3d mu = Eigen::Vector3d::Zero();
                    for (std::size_t t = 0; t < used; ++t) mu += Eigen::Map<const Eigen::Vector3f>(&points[3 * idx[t]]).cast<double>();
                    mu /= static_cast<double>(used);
                    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
                    for (std::size_t t = 0; t < used; ++t) {
                        const Eigen::Vector3d d = Eigen::Map<const Eigen::Vector3f>(&points[3 * idx[t]]).cast<double>() - mu;
                        cov += d * d.transpose();
                    }
                    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
                    nrm = eig.eigenvectors().col(0);  // smallest eigenvalue
                    // Canonical sign (a flat Gaussian does not care; the output should not
                    // depend on the solver's choice): largest component positive.
                    Eigen::Index a;
                    nrm.cwiseAbs().maxCoeff(&a);
                    if (nrm[a] < 0.0) nrm = -nrm;
                }
                Eigen::Vector3d t1;
                double stretch = 1.0;
                if (cam) {
                    const Eigen::Vector3d ray = (p - cam->position()).normalized();
                    if (nrm.dot(ray) > 0.0) nrm = -nrm;  // face the camera
                    const double cos_theta = std::abs(nrm.dot(ray));
                    const Eigen::Vector3d along = ray - ray.dot(nrm) * nrm;
                    t1 = along.norm() > 1e-9 ? along.normalized() : any_tangent(nrm);
                    stretch = std::min(1.0 / std::max(cos_theta, 1e-12), o.max_stretch);
                } else {
                    t1 = any_tangent(nrm);
                }
                Eigen::Matrix3d R;
                R.col(0) = t1;
                R.col(1) = nrm.cross(t1);
                R.col(2) = nrm;
                q = Eigen::Quaterniond(R);
                axes = Eigen::Vector3d(s * stretch, s, s * o.thickness);
            }
            q.normalize();
            if (q.w() < 0.0) q.coeffs() = -q.coeffs();
            for (int a = 0; a < 3; ++a)
                out.scales[3 * j + a] = static_cast<float>(std::max(axes[a], o.min_scale));
            out.rotations[4 * j + 0] = static_cast<float>(q.w());
            out.rotations[4 * j + 1] = static_cast<float>(q.x());
            out.rotations[4 * j + 2] = static_cast<float>(q.y());
            out.rotations[4 * j + 3] = static_cast<float>(q.z());
            for (int c = 0; c < 3; ++c)
                out.sh[3 * j + c] = static_cast<float>((m.colors[3 * i + c] - 0.5) / c0);
            if (m.confidence) {
                out.confidence[j] = m.confidence[i];
                out.opacities[j] = static_cast<float>(
                    fusion_weights::confidence_probability<double>(m.confidence[i], o.confidence_mapping));
            } else {
                out.opacities[j] = static_cast<float>(o.default_opacity);
            }
        }
    }
    return out;
}

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
