// SparseVoxelGrid: the occupied voxels of a point set and the grouping of its samples by voxel.
//
// Voxel of a point (as the AVSplat and AnySplat papers; README, "Occupancy-guided voxel fusion"): k = round(p / voxel_size)
// per axis, with p / voxel_size computed in double and rounded half away from zero (std::round,
// not the ties-to-even std::nearbyint: 0.5 -> 1, -0.5 -> -1, 2.5 -> 3). Keys are int32 per axis;
// a point whose key does not fit is an error, never a wrap.
//
// Only occupied voxels exist. They are numbered 0..M-1 in lexicographic order of their keys
// (kx, then ky, then kz), and the samples are grouped in CSR form: the samples of voxel v are
// sample_indices()[voxel_offsets()[v] .. voxel_offsets()[v + 1]), listed in increasing input
// index. Both orders are functions of the point set alone, so the grid is the same for any
// thread count and, up to renaming the samples, for any permutation of the input.
//
// Cost: O(N) for the keys and a parallel LSD radix sort of 64-bit packed keys (the keys are made
// relative to their bounding box and packed with the sample index; a few passes of at most 11
// bits), falling back to a parallel comparison sort, O(N log N), when the key range and N
// together need more than 64 bits. Memory: 16 bytes per sample of scratch while building (one
// more per sample when samples may be dropped); afterwards 8 bytes per sample (sample_indices,
// sample_voxel) and 20 per voxel (keys, offsets).
#pragma once

#include "avsplat/core/invalid_policy.h"

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace avsplat {

class SparseVoxelGrid {
public:
    SparseVoxelGrid() = default;

    /// Groups n samples by voxel.
    ///   positions   n x 3 float32, row-major (may be null when n == 0)
    ///   voxel_size  edge length, finite and > 0
    ///   on_invalid  a sample with a NaN or Inf coordinate throws (Raise) or is dropped (Drop)
    ///   keep        optional n flags; samples whose flag is 0 are left out and counted as
    ///               dropped (callers use it to drop samples invalid in other fields)
    ///   name        the field name used in error messages ("positions", "GaussianCloud.means")
    /// Throws std::invalid_argument for a bad voxel_size, for n >= 2^31, for a non-finite
    /// coordinate under Raise ("positions[i, axis] = nan: ..."), and, under either policy, for a
    /// coordinate whose key does not fit int32 ("positions[i, axis] = 1e+07: key
    /// round(p / voxel_size) = 1e+10 does not fit int32 ..."); the index is the first bad one.
    SparseVoxelGrid(const float* positions, std::size_t n, double voxel_size,
                    InvalidPolicy on_invalid = InvalidPolicy::Raise,
                    const std::uint8_t* keep = nullptr, const char* name = "positions");

    double voxel_size() const noexcept { return voxel_size_; }
    /// N: samples given, including the dropped ones.
    std::size_t num_samples() const noexcept { return sample_voxel_.size(); }
    /// M: occupied voxels.
    std::size_t num_voxels() const noexcept { return voxel_coords_.size() / 3; }
    /// Samples left out (invalid positions dropped, or keep[i] == 0).
    std::size_t dropped() const noexcept { return num_samples() - sample_indices_.size(); }

    /// M x 3 integer keys (kx, ky, kz), lexicographically increasing.
    const std::vector<std::int32_t>& voxel_coords() const& noexcept { return voxel_coords_; }
    /// On an rvalue (std::move(grid).voxel_coords()): moves the keys out instead of copying.
    std::vector<std::int32_t> voxel_coords() && noexcept { return std::move(voxel_coords_); }
    /// M + 1 offsets into sample_indices(); voxel_offsets()[0] == 0, back() == N - dropped().
    const std::vector<std::int64_t>& voxel_offsets() const noexcept { return voxel_offsets_; }
    /// N - dropped() input indices grouped by voxel, increasing within a voxel.
    const std::vector<std::int32_t>& sample_indices() const noexcept { return sample_indices_; }
    /// N entries: the voxel of each input sample, -1 for a dropped sample.
    const std::vector<std::int32_t>& sample_voxel() const& noexcept { return sample_voxel_; }
    /// On an rvalue: moves the map out instead of copying.
    std::vector<std::int32_t> sample_voxel() && noexcept { return std::move(sample_voxel_); }

    /// Samples in voxel v (v < num_voxels(), unchecked).
    std::int32_t occupancy(std::size_t v) const noexcept {
        return static_cast<std::int32_t>(voxel_offsets_[v + 1] - voxel_offsets_[v]);
    }
    /// M samples-per-voxel counts.
    std::vector<std::int32_t> occupancy() const;
    /// Largest occupancy (0 when there are no voxels).
    std::int32_t max_occupancy() const noexcept { return max_occupancy_; }

private:
    double voxel_size_ = 0.0;
    std::int32_t max_occupancy_ = 0;
    std::vector<std::int32_t> voxel_coords_;
    std::vector<std::int64_t> voxel_offsets_{0};
    std::vector<std::int32_t> sample_indices_;
    std::vector<std::int32_t> sample_voxel_;
};

}  // namespace avsplat
