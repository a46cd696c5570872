// Similarity transforms (rotation, translation, scale) and their robust estimation from point
// correspondences: a confidence-weighted Umeyama fit made robust by iteratively reweighted least
// squares with the Cauchy loss.
#pragma once

#include <Eigen/Core>

#include <cstddef>

namespace avsplat {

/// x -> scale * rotation * x + translation (rotation proper, scale > 0).
struct Similarity {
    Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
    Eigen::Vector3d translation = Eigen::Vector3d::Zero();
    double scale = 1.0;

    Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return scale * (rotation * x) + translation; }
    /// The transform that undoes this one.
    Similarity inverse() const;
    /// (*this) after `other`: x -> this(other(x)).
    Similarity operator*(const Similarity& other) const;
    /// The 4 x 4 matrix [scale R, t; 0, 1].
    Eigen::Matrix4d matrix() const;
};

/// How similarity_from_correspondences down-weights outliers.
struct RobustFitOptions {
    /// Constant k of the Cauchy loss rho(r) = k^2 / 2 log(1 + (r / k)^2), as a fraction of the
    /// scene size (the weighted RMS distance of the target points from their centroid). Each
    /// iteration weighs correspondence i by c_i / (1 + (r_i / k)^2), r_i its residual distance.
    /// 0 gives the plain weighted Umeyama fit. Must be finite and >= 0.
    double loss_scale = 0.02;
    /// IRLS iterations at most (>= 1); iteration stops earlier when the transform moves by less
    /// than 1e-10 (relative).
    int iterations = 30;
};

/// A fitted similarity and how well it fits.
struct SimilarityFit {
    Similarity transform;        ///< maps source points onto target points
    double rms_residual = 0.0;   ///< weighted RMS of |target - transform(source)| (final weights)
    double scene_size = 0.0;     ///< the target's RMS spread about its weighted centroid
    double effective_count = 0.0;///< (sum of final weights)^2 / sum of squared final weights
    int iterations = 0;          ///< IRLS iterations run
};

/// The similarity T minimising sum_i w_i rho(|target_i - T(source_i)|) (Umeyama's closed form
/// inside IRLS, in double). source, target: n x 3 row-major; weights: n values >= 0 (the
/// confidences), or null for all 1. Cost O(n) per iteration; sequential sums, so the result
/// does not depend on the thread count.
/// Throws std::invalid_argument for n < 3, a non-finite point or a negative or non-finite
/// weight (naming the index), all weights 0, or degenerate geometry: source or target points
/// that are (nearly) collinear or coincident, whose rotation is not determined.
SimilarityFit similarity_from_correspondences(const float* source, const float* target, std::size_t n,
                                              const float* weights = nullptr,
                                              const RobustFitOptions& options = {});

}  // namespace avsplat
