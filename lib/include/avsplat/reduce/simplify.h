// simplify: reduce a scene to a budget of Gaussians with the least image error.
//
// The budget is one of: a target count, a ratio of the input count, or a rendered error bound at
// given cameras. Two methods:
//
//   Merge  rounds of greedy pairwise merging of nearby Gaussians by moment matching (mean and
//          covariance of the pair weighted by opacity x surface area; SH, confidence and extra
//          channels averaged with the same weights), cheapest pair first by a cost of shape,
//          lost opacity and colour (every SH band), at most 40 % of the Gaussians per round,
//          until the target count is met exactly. Rows come out in Morton order of their means.
//   Voxel  occupancy-guided fusion (fuse_gaussians, policy Occupancy, shape Moment) at the voxel
//          size found by bisection on log(voxel size) whose count is within 2 % of the target
//          (else the closest, and output_count says what it gave). Without a confidence, one is
//          made from the opacity: logit(clamp(opacity, 1e-6, 1 - 1e-6)).
//
// With max_error and cameras, the count is the smallest that keeps the rendered error at or under
// max_error, found by bisection on log(count) (12 steps, or until the bracket is within 2 %). The
// error is the root mean square difference of the rendered colour (RGB in [0, 1], over every
// pixel, channel and camera) between the simplified and the input cloud, rendered with
// SimplifyOptions::render. Whenever cameras are given, `error` is measured for the result.
//
// Determinism: both methods put the input in a canonical order first, so results are
// bit-identical for any permutation of the input and any number of OpenMP threads.
// The cost, its constants and how they were chosen: docs/design/reduction.md.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"

#include <cstddef>
#include <functional>
#include <optional>
#include <vector>

namespace avsplat {

enum class SimplifyMethod { Merge, Voxel };

/// The budget (exactly one of target_count, ratio, max_error) and the method.
struct SimplifyOptions {
    std::optional<std::size_t> target_count;  ///< >= 1; a target >= N returns the input
    std::optional<double> ratio;              ///< in (0, 1]; target = max(1, round(ratio * N))
    std::optional<double> max_error;          ///< > 0, RMSE of rendered colour; needs cameras
    SimplifyMethod method = SimplifyMethod::Merge;
    RenderOptions render;                     ///< how `error` is rendered (CPU by default)
    /// With max_error: called after each simplification the search tries, with the number tried
    /// and the most it can try (kMaxErrorSearches); for a progress display. Unset: not called.
    std::function<void(int tried, int most)> progress;
};

/// The most simplifications a max_error search tries (the count 1, then a bisection).
constexpr int kMaxErrorSearches = 13;

/// Throws std::invalid_argument naming the first bad field ("SimplifyOptions.ratio: ...").
void validate(const SimplifyOptions& options);

/// What simplify did.
struct SimplifyResult {
    GaussianCloud cloud;            ///< the simplified cloud
    std::size_t input_count = 0;    ///< N
    std::size_t target_count = 0;   ///< the count asked for (or found, with max_error)
    std::size_t output_count = 0;   ///< cloud.size()
    SimplifyMethod method = SimplifyMethod::Merge;
    /// Voxel: the voxel size used. Merge: NaN.
    double voxel_size = 0.0;
    /// Merge: merge rounds. Voxel: bisection steps on the voxel size.
    int iterations = 0;
    /// RMSE of rendered colour against the input at the given cameras; NaN without cameras.
    double error = 0.0;
    /// With max_error: the simplifications tried by the search on the count; else 1.
    int searches = 1;
};

/// Simplifies `cloud` to the budget in `options` (see the file comment for the methods).
///   cloud    a valid cloud (validate()); its SH degree, confidence and extras are kept
///   cameras  where the error is measured; required with max_error, optional otherwise
/// Throws std::invalid_argument for an invalid cloud (naming the field and index), a bad option,
/// max_error without cameras or an invalid camera; avsplat::Interrupted when the caller's
/// interrupt check says stop. Progress (avsplat/core/progress.h): with a count or ratio, the
/// Gaussians removed of those to remove, after each merge round (voxel: start and end); with
/// max_error, the simplifications tried of kMaxErrorSearches.
SimplifyResult simplify(const GaussianCloud& cloud, const SimplifyOptions& options,
                        const std::vector<Camera>& cameras = {});

}  // namespace avsplat
