#include "avsplat/point_maps/point_maps.h"
#include "core/confidence_mapping.h"

#include "avsplat/core/sh.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include "core/interrupt_poll.h"
#include "common/kdtree.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

using detail::KdTree;

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
            if (!confidence::confidence_valid(c, o.confidence_mapping))
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

    InterruptPoll poll;
#pragma omp parallel
    {
        std::vector<std::uint32_t> idx;
        std::vector<double> d2;
        poll.guard([&] {  // std::bad_alloc stops the loop and is rethrown after the region
            idx.resize(k_query);
            d2.resize(k_query);
        });
#pragma omp for schedule(static)
        for (std::int64_t jj = 0; jj < static_cast<std::int64_t>(n); ++jj) {
            if (poll.stop(jj)) continue;
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
                    confidence::confidence_probability<double>(m.confidence[i], o.confidence_mapping));
            } else {
                out.opacities[j] = static_cast<float>(o.default_opacity);
            }
        }
    }
    poll.throw_if_stopped();
    return out;
}


}  // namespace avsplat
