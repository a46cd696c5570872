// Geometry metrics between point sets: nearest distances, statistical outlier removal (Open3D's
// rules) and the DTU / Tanks-and-Temples accuracy, completeness, chamfer and F-score.
// Point sets are n x 3 row-major float32 arrays; distances are accumulated in double and summed
// in a fixed order, so results do not depend on the number of threads.
#pragma once

#include <cstddef>
#include <vector>

namespace avsplat {

/// Statistical outlier removal with Open3D's rule and names (RemoveStatisticalOutliers):
/// m_i = mean distance from point i to its nb_neighbors nearest points, the point itself
/// counted as one of them (as Open3D); a point is kept when m_i <= mean(m) + std_ratio * std(m)
/// (std with Bessel's correction; at n = 1 every point is kept). Unlike Open3D, a point exactly
/// at the threshold is kept, so that a perfectly regular grid is not emptied.
/// `points` is n x 3 float32. Returns the indices of the kept points, ascending.
/// Throws std::invalid_argument for nb_neighbors < 1, std_ratio < 0 or not finite, or a
/// non-finite point (naming its index).
std::vector<std::size_t> remove_statistical_outliers(const float* points, std::size_t n,
                                                     int nb_neighbors = 20,
                                                     double std_ratio = 2.0);

/// For each of the n_source points, the Euclidean distance to the nearest of the n_target
/// points (Open3D's ComputePointCloudDistance). Both arrays are n x 3 float32. Throws
/// std::invalid_argument for a non-finite point or an empty target with a non-empty source.
std::vector<double> compute_point_cloud_distance(const float* source, std::size_t n_source,
                                                 const float* target, std::size_t n_target);

/// Accuracy / completeness of a predicted point set against a ground-truth one (the DTU and
/// Tanks-and-Temples measures), distances in world units.
struct AccuracyCompleteness {
    double accuracy = 0.0;      ///< mean distance from a predicted point to the ground truth
    double completeness = 0.0;  ///< mean distance from a ground-truth point to the prediction
    double chamfer = 0.0;       ///< (accuracy + completeness) / 2
    double precision = 0.0;     ///< fraction of predicted points closer than threshold
    double recall = 0.0;        ///< fraction of ground-truth points closer than threshold
    double fscore = 0.0;        ///< 2 P R / (P + R), 0 when P + R = 0
    double threshold = 0.0;     ///< the threshold used
};

/// Accuracy, completeness, chamfer and the F-score at `threshold` (> 0, finite; "closer" is
/// strictly less, as Tanks and Temples) between n_pred and n_gt points (n x 3 float32).
/// Throws std::invalid_argument for an empty set, a non-finite point or a bad threshold.
AccuracyCompleteness accuracy_completeness(const float* pred, std::size_t n_pred,
                                           const float* gt, std::size_t n_gt,
                                           double threshold);

/// Symmetric chamfer distance (mean nearest distance a -> b + mean b -> a) / 2, with plain
/// (not squared) distances as DTU. Throws std::invalid_argument for an empty set or a
/// non-finite point.
double chamfer_distance(const float* a, std::size_t n_a, const float* b, std::size_t n_b);

}  // namespace avsplat
