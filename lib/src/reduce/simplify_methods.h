// The two methods behind simplify (avsplat/reduce/simplify.h), one file each.
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>

namespace avsplat::reduce_detail {

/// Merge: rounds of greedy pairwise merging until exactly `target` Gaussians are left
/// (1 <= target < cloud.size()). `cloud` is valid and in canonical order. `rounds` counts the
/// rounds.
GaussianCloud merge_to_count(const GaussianCloud& cloud, std::size_t target, int& rounds);

/// Voxel: occupancy-guided fusion at the voxel size found by bisection (1 <= target <
/// cloud.size()). Sets `voxel_size` and `steps` (voxel counts tried).
GaussianCloud voxel_to_count(const GaussianCloud& cloud, std::size_t target, double& voxel_size, int& steps);

}  // namespace avsplat::reduce_detail
