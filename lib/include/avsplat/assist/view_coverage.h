// Greedy coverage selection of views on predicted point maps: which views add geometry that the
// views already chosen do not cover.
//
// AVSplat's Assist-View selection picks, for each view, a small set of views that cover what it
// sees (assist_selection.h, on tokens). The same greedy coverage serves the geometry side: with
// many input views, most add little, and leaving them out saves fusion time and memory. Here a
// view covers the voxels its valid points fall in (the voxel rule of SparseVoxelGrid, the one
// fusion uses), and views are taken in order of the voxels they add to those already covered.
//
// Algorithm: lazy greedy (Minoux 1978). Coverage is submodular, so a view's gain can only shrink
// as views are chosen; a view's last computed gain is an upper bound, and a view whose recomputed
// gain still beats every other bound is the greedy choice. The result is exactly that of plain
// greedy: at each step the view of largest gain, ties to the smaller view index. It covers at
// least (1 - 1/e) of the voxels the best set of the same size covers.
//
// Cost: one SparseVoxelGrid over all points (a radix sort), a sort per view of its voxel ids, and
// gains recomputed only when a view reaches the top of the queue. Deterministic; the result does
// not depend on the thread count or on the order of the pixels within a view.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat {

struct ViewCoverageOptions {
    /// Voxel edge length (finite, > 0).
    double voxel_size = 0.0;
    /// Stop after this many views; 0: no budget (every view that passes min_gain is ordered).
    std::size_t budget = 0;
    /// Stop when the best remaining view adds fewer than min_gain * (all voxels the views cover
    /// together) voxels; in [0, 1]. 0 orders every view (those adding nothing come last, by
    /// index).
    double min_gain = 0.0;
    /// With a confidence map, only pixels whose confidence is > min_confidence count.
    double min_confidence = 0.0;
};

struct ViewCoverage {
    /// The chosen views, in the order greedy picked them.
    std::vector<std::int64_t> order;
    /// Voxels each pick added (gains[i] for order[i]).
    std::vector<std::int64_t> gains;
    /// Voxels covered after each pick (the running sum of gains).
    std::vector<std::int64_t> coverage;
    /// Voxels covered by all views together (the denominator of min_gain).
    std::int64_t total_voxels = 0;
    /// Pixels that counted (valid, confidence above the threshold).
    std::int64_t points_used = 0;
};

/// Orders the views of S x H x W point maps by greedy coverage.
///   points      S x H x W x 3 float32 world positions, row-major
///   confidence  S x H x W float32, or null (every pixel counts)
///   valid       S x H x W, non-zero where the pixel holds a prediction, or null (all do);
///               invalid pixels are not read
/// Throws std::invalid_argument for negative dimensions, a bad option, a non-finite point
/// ("points[s, row, col, axis] = nan", naming the flat pixel index too) or confidence in a valid
/// pixel, and a key that does not fit int32 (as SparseVoxelGrid).
ViewCoverage select_views_by_coverage(const float* points, const float* confidence,
                                      const std::uint8_t* valid, int views, int height, int width,
                                      const ViewCoverageOptions& options);

}  // namespace avsplat
