// FusionStream: fuse_voxels / fuse_gaussians on an input larger than memory, fed chunk by chunk.
//
// Fusion is local: a voxel's result depends only on its own samples, put in a canonical order
// before any arithmetic, and the voxels come out in lexicographic order of their keys
// k = round(p / voxel_size) (computed in double). So the key space can be cut into blocks that
// are ranges of that order, each block fused alone with the in-memory operator, and the blocks'
// results concatenated in key order: the result is the in-memory operator's on the concatenated
// input, bit for bit, diagnostics included.
//
// Blocks are ranges of voxel keys (kx, ky, kz) in lexicographic order. Chunks are held in
// memory until they reach a quarter of memory_limit; at the first overflow the block boundaries
// are chosen from the key quantiles of what has arrived so far (so a dense object gets many
// small blocks and a sparse background few large ones), and from then on every chunk is routed
// to per-block spill files in the work folder. finish() fuses the blocks in order; a block that
// has grown past a quarter of memory_limit is first split again by the key quantiles of its own
// samples (two streaming passes over its file). Only a single voxel is never split.
//
// Sample bookkeeping is global: sample i is the i-th sample added, over all chunks in the order
// they were added, and sample_voxel indexes the concatenated voxels. Invalid samples follow
// params.on_invalid as in the in-memory operator, checked by the operator's own checks on each
// chunk as it is added: Drop drops them in add() (counted in `dropped`); Raise raises from the
// add() of the first chunk that holds one, with the operator's message for that chunk and the
// global index, so a bad sample stops the stream before anything more is spilled.
//
// The work folder (a fresh subfolder of work_dir, or of the system's temporary folder) is
// removed when finish() returns or throws and when the stream is destroyed.
//
// A stream is not thread-safe: a call made while another thread's call on the same stream runs
// throws std::logic_error. An add() that fails after its chunk passed the checks (a spill file
// that cannot be written, memory) closes the stream: its files are removed and every later
// call throws std::logic_error naming the first failure.
#pragma once

#include "avsplat/core/gaussians.h"
#include "avsplat/fusion/fusion.h"

#include <cstddef>
#include <cstdint>
#include <functional>
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

    /// Receives one block's fused voxels (see the finish overloads below).
    using FeatureSink = std::function<void(FeatureFusionResult&& block)>;
    using GaussianSink = std::function<void(GaussianFusionResult&& block)>;
    /// As finish() / finish_gaussians(), but hands each block's fused voxels to `sink` as soon as
    /// they are fused, in key order, and keeps none of them, so that memory holds one block's
    /// result at a time (write them with GaussianPlyWriter, io/ply.h, for a PLY file). The blocks
    /// concatenated are what finish() / finish_gaussians() return; a block's sample_voxel is
    /// left empty. Returns the whole input's sample_voxel (global sample -> global voxel) and
    /// `dropped`, and no voxels.
    FeatureFusionResult finish(const FeatureSink& sink);
    GaussianFusionResult finish_gaussians(const GaussianSink& sink);

    /// Called by finish with (samples fused so far, samples added), once before the first block
    /// and after each block, so that a caller can show progress (or throw to stop). The same
    /// reports reach the installed ProgressCallback (avsplat/core/progress.h).
    using Progress = std::function<void(std::size_t done, std::size_t total)>;
    void set_progress(Progress progress);

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
