// FusionStream: fuse_voxels / fuse_gaussians on an input larger than memory, fed chunk by chunk.
//
// Fusion is local: a voxel's result depends only on its own samples, put in a canonical order
// before any arithmetic, and the voxels come out in lexicographic order of their keys
// k = round(p / voxel_size) (computed in double). So the key space can be cut into blocks that
// are ranges of that order, each block fused alone with the in-memory operator, and the blocks'
// results concatenated in key order: the result is the in-memory operator's on the concatenated
// input, bit for bit, diagnostics included.
//
// The stream cuts by the first key component kx. Chunks are held in memory until they reach a
// quarter of memory_limit; at the first overflow the block boundaries are chosen from the kx
// quantiles of what has arrived so far (so a dense object gets many narrow blocks and a sparse
// background few wide ones), and from then on every chunk is routed to per-block spill files in
// the work folder. finish() fuses the blocks in order; a block that has grown past a quarter of
// memory_limit is first split again by the kx quantiles of its own samples (two streaming passes
// over its file). A single kx slab is never split, so a slab larger than the limit is fused whole.
//
// Sample bookkeeping is global: sample i is the i-th sample added, over all chunks in the order
// they were added, and sample_voxel indexes the concatenated voxels. Invalid samples follow
// params.on_invalid as in the in-memory operator; with Raise, a non-finite position throws from
// add(), other invalid fields from finish() (the index in the message is the global one, but
// the first bad sample reported is the first of the first block that has one).
//
// The work folder (a fresh subfolder of work_dir, or of the system's temporary folder) is
// removed when finish() returns or throws and when the stream is destroyed.
#pragma once

#include "avsplat/core/gaussians.h"
#include "avsplat/fusion/fusion.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace avsplat {

class FusionStream {
public:
    /// voxel_size > 0 and finite; params as fuse_voxels / fuse_gaussians (validated here);
    /// memory_limit in bytes for the buffered input and each block's fusion (0: 1 GiB); work_dir
    /// an existing folder for the spill files ("" : the system's temporary folder).
    /// Throws std::invalid_argument for a bad voxel_size or params, avsplat::IOError when the
    /// work folder cannot be created.
    FusionStream(double voxel_size, const FusionParams& params = {}, std::size_t memory_limit = 0,
                 const std::string& work_dir = "");
    ~FusionStream();
    FusionStream(const FusionStream&) = delete;
    FusionStream& operator=(const FusionStream&) = delete;

    /// Adds n samples for fuse_voxels (arguments as fuse_voxels: positions n x 3, features
    /// n x channels, confidence n or null). Every chunk must have the same channels and either
    /// all or none a confidence; a stream takes features or Gaussians, not both. Throws
    /// std::invalid_argument naming the field otherwise, or for a non-finite position (Raise) or
    /// a key outside int32; avsplat::IOError when a spill file cannot be written. The data are
    /// copied; the caller's buffers may be reused on return.
    void add(const float* positions, std::size_t n, const float* features, int channels,
             const float* confidence = nullptr);

    /// Adds the Gaussians of `chunk` for fuse_gaussians. Every chunk must have the same SH
    /// degree, confidence presence and extra channel names (in order); shape errors throw
    /// std::invalid_argument.
    void add_gaussians(const GaussianCloud& chunk);

    /// fuse_voxels on everything added (the stream must have had add() calls, or none).
    /// The stream is spent afterwards; a second finish throws std::logic_error.
    FeatureFusionResult finish();
    /// fuse_gaussians on everything added (the stream must have had add_gaussians() calls, or none).
    GaussianFusionResult finish_gaussians();

    bool takes_gaussians() const noexcept;      ///< add_gaussians() was called
    std::size_t num_samples() const noexcept;   ///< samples added so far
    /// Spill files made so far: the blocks of the first spill, plus those finish() made by
    /// splitting a block again (0 while everything is in memory).
    std::size_t num_blocks() const noexcept;
    std::size_t spilled_bytes() const noexcept; ///< bytes written to spill files so far
    const std::string& work_folder() const noexcept;  ///< "" until the first spill

private:
    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace avsplat
