// The Morton (Z-curve) order of a cloud's means, as splat-transform sorts Gaussians: the order
// compressed PLY files are written in, and the order the merge simplifier works in.
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <vector>

namespace avsplat {

/// The order write_compressed_ply(..., true) (io/compressed_ply.h) writes the Gaussians in:
/// order[i] is the input index of the i-th Gaussian in the file. splat-transform's Morton sort: 10 bits per axis over
/// the bounds of the means, ties in input order, buckets of more than 256 equal codes sorted
/// again over their own bounds.
std::vector<std::size_t> morton_order(const GaussianCloud& cloud);

/// morton_order of the rows `rows` of `cloud` (each < cloud.size()): the same sort over the
/// bounds of their means, ties in the order of `rows`. morton_order(c, order) is
/// morton_order(select(c, order)) mapped back through `order`, without copying the cloud.
std::vector<std::size_t> morton_order(const GaussianCloud& cloud, std::vector<std::size_t> rows);

}  // namespace avsplat
