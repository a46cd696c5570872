// Stitching: align the chunks of a long capture, move every chunk's Gaussians into chunk 0's
// frame, and fuse them with the voxel operator so that overlapping surfaces become one layer.
#pragma once

#include "avsplat/fusion/fusion.h"
#include "avsplat/registration/chunk_alignment.h"

#include <cstddef>
#include <string>
#include <vector>

namespace avsplat {

struct StitchOptions {
    AlignmentOptions alignment;
    /// false: concatenate the moved chunks without fusing them (a baseline).
    bool fuse = true;
    /// > 0: fuse through a FusionStream with this memory limit in bytes (chunks spill to
    /// `work_dir`); 0: fuse_gaussians in memory.
    std::size_t memory_limit = 0;
    std::string work_dir;
};

struct StitchResult {
    GaussianCloud cloud;            ///< in chunk 0's frame
    ChunkAlignment alignment;       ///< the transforms and residuals
    std::size_t input_gaussians = 0;
};

/// align_chunks, then fuse_chunks with its transforms.
StitchResult stitch(const std::vector<PredictionChunk>& chunks, double voxel_size, const FusionParams& params = {},
                    const StitchOptions& options = {});

/// Moves chunk i's Gaussians by transforms[i] (core/transform.h: SH rotated exactly, scales
/// multiplied) and fuses them all (fuse_gaussians, or a FusionStream when options.memory_limit
/// > 0; concatenated when !options.fuse). Throws std::invalid_argument for a transform count
/// that differs from the chunk count, a chunk without Gaussians (naming it), chunks whose SH
/// degrees or channels differ, and fusion's errors.
GaussianCloud fuse_chunks(const std::vector<PredictionChunk>& chunks, const std::vector<Similarity>& transforms,
                          double voxel_size, const FusionParams& params = {}, const StitchOptions& options = {});

}  // namespace avsplat
