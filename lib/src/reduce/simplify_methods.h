// The two methods behind simplify (avsplat/reduce/simplify.h), one file each, and the pieces of
// the Merge method's rounds that the tests hold to their brute-force reference.
#pragma once

#include "avsplat/core/gaussians.h"
#include "reduce/moment_merge.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat::reduce_detail {

/// Merge: rounds of greedy pairwise merging until exactly `target` Gaussians are left
/// (1 <= target < cloud.size()). `cloud` is valid; `order` is its canonical order (the rounds
/// read the rows in that order, so the result does not depend on the input order). `rounds`
/// counts the rounds.
GaussianCloud merge_to_count(const GaussianCloud& cloud, const std::vector<std::size_t>& order, std::size_t target,
                             int& rounds);

/// No partner (round_pairs).
constexpr std::uint32_t kNone = 0xffffffffu;

/// The pairs one Merge round takes on `in` (n >= 2 rows, MergeInput rows `g`): the candidates
/// are (i, j) with j among i's `neighbours` nearest means or i among j's (exact: squared
/// distances in double, ties by the nearer index |i - j|, then the smaller; common/all_knn.h;
/// neighbours <= 32); they are taken greedily in increasing (merge_cost, smaller index, larger
/// index) while both ends are free, until `needed` pairs are taken or none is left. Returns
/// partner[i]: the row i merges with, or kNone. (Candidates are ordered by
/// merge_cost_lower_bound and priced only when the scan reaches them with both ends free; the
/// pairs are those of a full sort by cost.) merge_to_count asks for 8 neighbours in its first
/// round and 12 in the later ones (simplify_merge.cpp).
std::vector<std::uint32_t> round_pairs(const GaussianCloud& in, const std::vector<MergeInput>& g, std::size_t needed,
                                       std::size_t neighbours);

/// Voxel: occupancy-guided fusion at the voxel size found by bisection (1 <= target <
/// cloud.size()). Sets `voxel_size` and `steps` (voxel counts tried).
GaussianCloud voxel_to_count(const GaussianCloud& cloud, std::size_t target, double& voxel_size, int& steps);

}  // namespace avsplat::reduce_detail
