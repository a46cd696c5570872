// Weighted Umeyama inside iteratively reweighted least squares (Cauchy loss).
#include "avsplat/registration/similarity.h"

#include <Eigen/Dense>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

Similarity Similarity::inverse() const {
    Similarity inv;
    inv.rotation = rotation.transpose();
    inv.scale = 1.0 / scale;
    inv.translation = -(inv.scale * (inv.rotation * translation));
    return inv;
}

Similarity Similarity::operator*(const Similarity& o) const {
    Similarity r;
    r.rotation = rotation * o.rotation;
    r.scale = scale * o.scale;
    r.translation = scale * (rotation * o.translation) + translation;
    return r;
}

Eigen::Matrix4d Similarity::matrix() const {
    Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
    m.block<3, 3>(0, 0) = scale * rotation;
    m.block<3, 1>(0, 3) = translation;
    return m;
}

namespace {

// Points are degenerate when the second principal spread is below this fraction of the first:
// (nearly) collinear points leave the rotation about their line undetermined.
constexpr double kDegenerateRatio = 1e-8;

struct Moments {
    Eigen::Vector3d mean_s = Eigen::Vector3d::Zero(), mean_t = Eigen::Vector3d::Zero();
    Eigen::Matrix3d cov_ts = Eigen::Matrix3d::Zero(), cov_ss = Eigen::Matrix3d::Zero(),
                    cov_tt = Eigen::Matrix3d::Zero();
    double total = 0.0;
};

Moments moments(const float* s, const float* t, std::size_t n, const std::vector<double>& w) {
    Moments m;
    for (std::size_t i = 0; i < n; ++i) {
        if (w[i] == 0.0) continue;
        m.total += w[i];
        for (int c = 0; c < 3; ++c) {
            m.mean_s[c] += w[i] * s[3 * i + c];
            m.mean_t[c] += w[i] * t[3 * i + c];
        }
    }
    m.mean_s /= m.total;
    m.mean_t /= m.total;
    for (std::size_t i = 0; i < n; ++i) {
        if (w[i] == 0.0) continue;
        const Eigen::Vector3d ds = Eigen::Vector3d(s[3 * i], s[3 * i + 1], s[3 * i + 2]) - m.mean_s;
        const Eigen::Vector3d dt = Eigen::Vector3d(t[3 * i], t[3 * i + 1], t[3 * i + 2]) - m.mean_t;
        m.cov_ts += w[i] * dt * ds.transpose();
        m.cov_ss += w[i] * ds * ds.transpose();
        m.cov_tt += w[i] * dt * dt.transpose();
    }
    m.cov_ts /= m.total;
    m.cov_ss /= m.total;
    m.cov_tt /= m.total;
    return m;
}

bool degenerate(const Eigen::Matrix3d& cov) {
    const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues();  // ascending
    return !(ev[2] > 0.0) || ev[1] < kDegenerateRatio * ev[2];
}

Similarity umeyama(const Moments& m) {
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m.cov_ts, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Vector3d d = Eigen::Vector3d::Ones();
    if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) d[2] = -1.0;
    Similarity T;
    T.rotation = svd.matrixU() * d.asDiagonal() * svd.matrixV().transpose();
    T.scale = svd.singularValues().dot(d) / m.cov_ss.trace();
    T.translation = m.mean_t - T.scale * (T.rotation * m.mean_s);
    return T;
}

}  // namespace

SimilarityFit similarity_from_correspondences(const float* source, const float* target, std::size_t n,
                                              const float* weights, const RobustFitOptions& options) {
    if (!(std::isfinite(options.loss_scale) && options.loss_scale >= 0.0))
        throw std::invalid_argument("similarity_from_correspondences: loss_scale must be finite and >= 0");
    if (options.iterations < 1)
        throw std::invalid_argument("similarity_from_correspondences: iterations must be >= 1");
    if (n < 3)
        throw std::invalid_argument("similarity_from_correspondences: need at least 3 correspondences, got " +
                                    std::to_string(n));
    if (!source || !target) throw std::invalid_argument("similarity_from_correspondences: source and target are required");
    std::vector<double> base(n, 1.0);
    for (std::size_t i = 0; i < n; ++i) {
        for (int c = 0; c < 3; ++c) {
            if (!std::isfinite(source[3 * i + c]))
                throw std::invalid_argument("similarity_from_correspondences: source[" + std::to_string(i) + "] is not finite");
            if (!std::isfinite(target[3 * i + c]))
                throw std::invalid_argument("similarity_from_correspondences: target[" + std::to_string(i) + "] is not finite");
        }
        if (weights) {
            if (!(std::isfinite(weights[i]) && weights[i] >= 0.f))
                throw std::invalid_argument("similarity_from_correspondences: weights[" + std::to_string(i) +
                                            "] must be finite and >= 0");
            base[i] = weights[i];
        }
    }
    std::vector<double> w = base;
    Moments m = moments(source, target, n, w);
    if (!(m.total > 0.0)) throw std::invalid_argument("similarity_from_correspondences: every weight is 0");
    if (degenerate(m.cov_ss))
        throw std::invalid_argument("similarity_from_correspondences: degenerate geometry: the source points are "
                                    "(nearly) collinear or coincident");
    if (degenerate(m.cov_tt))
        throw std::invalid_argument("similarity_from_correspondences: degenerate geometry: the target points are "
                                    "(nearly) collinear or coincident");
    SimilarityFit fit;
    fit.scene_size = std::sqrt(m.cov_tt.trace());
    const double k = options.loss_scale * fit.scene_size;
    Similarity T = umeyama(m);
    fit.iterations = 1;
    for (int it = 1; it < options.iterations && k > 0.0; ++it) {
        for (std::size_t i = 0; i < n; ++i) {
            const Eigen::Vector3d s(source[3 * i], source[3 * i + 1], source[3 * i + 2]);
            const Eigen::Vector3d t(target[3 * i], target[3 * i + 1], target[3 * i + 2]);
            const double r = (t - T.apply(s)).norm() / k;
            w[i] = base[i] / (1.0 + r * r);
        }
        m = moments(source, target, n, w);
        if (degenerate(m.cov_ss) || degenerate(m.cov_tt))
            throw std::invalid_argument("similarity_from_correspondences: degenerate geometry: the inliers are "
                                        "(nearly) collinear");
        const Similarity next = umeyama(m);
        ++fit.iterations;
        const double change = (next.rotation - T.rotation).norm() + std::abs(std::log(next.scale / T.scale)) +
                              (next.translation - T.translation).norm() / fit.scene_size;
        T = next;
        if (change < 1e-10) break;
    }
    // The final weights and residual of the returned transform.
    double sum = 0.0, sum_sq = 0.0, sum_r2 = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const Eigen::Vector3d s(source[3 * i], source[3 * i + 1], source[3 * i + 2]);
        const Eigen::Vector3d t(target[3 * i], target[3 * i + 1], target[3 * i + 2]);
        const double r = (t - T.apply(s)).norm();
        const double wi = k > 0.0 ? base[i] / (1.0 + (r / k) * (r / k)) : base[i];
        sum += wi;
        sum_sq += wi * wi;
        sum_r2 += wi * r * r;
    }
    fit.transform = T;
    fit.rms_residual = sum > 0.0 ? std::sqrt(sum_r2 / sum) : 0.0;
    fit.effective_count = sum_sq > 0.0 ? sum * sum / sum_sq : 0.0;
    return fit;
}

}  // namespace avsplat
