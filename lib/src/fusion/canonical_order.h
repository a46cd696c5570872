// Canonical order of a voxel's samples: a total order on the sample contents (never on where
// the samples sit in the input), so that fusion results are bit-identical for any permutation
// of the input and any thread count.
//
// Samples are ordered by decreasing confidence when there is one (so the weights decrease along
// the voxel and trimming needs no sort), else by the bits of x; ties are broken by the bit
// patterns of the position (x, y, z), the confidence, the tie fields (features; or opacity,
// scales, rotations, SH, extras) and finally the input index. Samples equal in every field are
// interchangeable, so ordering them by index cannot change a result.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat::fusion_detail {

// A per-sample float row (width floats per sample, contiguous) that orders samples sharing a
// position and a confidence.
struct RowField {
    const float* data;
    std::size_t width;
};

// The fields that order samples sharing a position and a confidence, read by input index.
using TieFields = std::vector<RowField>;

// One voxel's samples: input indices, and positions and confidences gathered contiguously.
struct VoxelSamples {
    const std::int32_t* ids;
    const float* positions;   // n x 3
    const float* confidence;  // n, or null
    std::size_t n;
};

// Scratch memory of canonical_order, reused from voxel to voxel.
struct CanonicalScratch {
    std::vector<std::uint32_t> sort_keys;   // per slot: the primary key (confidence or x bits)
    std::vector<std::uint64_t> keyed_slots;  // (sort key << 32 | slot), for voxels over 16 samples
    std::vector<std::int32_t> slots;         // result: local slots in canonical order
};

// Sets scratch.slots[0..s.n) to the local slots 0..n-1 of the voxel's samples in canonical
// order; s.n >= 1. ties holds the tie fields, read by input index.
void canonical_order(const VoxelSamples& s, const TieFields& ties, CanonicalScratch& scratch);

}  // namespace avsplat::fusion_detail
