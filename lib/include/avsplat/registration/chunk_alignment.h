// Aligning the chunks of a long capture into one frame from the frames they share: the same
// pixel of the same frame, valid in both chunks, is a correspondence between their point maps.
#pragma once

#include "avsplat/registration/pose_graph.h"
#include "avsplat/registration/prediction_chunk.h"
#include "avsplat/registration/similarity.h"

#include <cstddef>
#include <vector>

namespace avsplat {

struct AlignmentOptions {
    RobustFitOptions fit;
    /// true: optimise all pairwise estimates together (optimize_pose_graph); false: chain them
    /// along the breadth-first spanning tree from chunk 0 (in chunk order).
    bool pose_graph = true;
    /// Pairs with fewer shared valid pixels than this (>= 3) give no estimate.
    int min_correspondences = 64;
};

/// The estimate of one pair of chunks that share frames.
struct PairAlignment {
    int a = 0;
    int b = 0;                       ///< a < b
    Similarity a_from_b;             ///< the robust fit x_a = T(x_b)
    std::size_t correspondences = 0; ///< shared valid pixels
    double rms_residual = 0.0;       ///< of the pairwise fit, in chunk a's units
    double scene_size = 0.0;         ///< spread of the shared points in chunk a's units
    /// RMS distance between the two chunks' points of the shared pixels after the final
    /// alignment, in chunk 0's units (weighted by the fit's final weights).
    double aligned_rms = 0.0;
};

struct ChunkAlignment {
    /// Chunk 0's frame from chunk i's: transforms[0] is the identity.
    std::vector<Similarity> transforms;
    std::vector<PairAlignment> pairs;  ///< every pair with an estimate, in (a, b) order
    /// Per chunk: RMS of aligned_rms over its pairs (chunk 0's units).
    std::vector<double> residuals;
    double initial_cost = 0.0;  ///< the pose graph's cost at the chained start (pose_graph only)
    double final_cost = 0.0;    ///< ... and after optimisation
};

/// Estimates every pair of chunks with min_correspondences shared valid pixels
/// (similarity_from_correspondences, weighted by the product of the two confidences'
/// probabilities), then the transforms (see AlignmentOptions::pose_graph). Deterministic for any
/// thread count. Cost O(shared pixels x fit iterations + pose graph).
/// Throws std::invalid_argument naming the chunk for: an invalid chunk (validate(), which
/// includes a chunk with no valid pixel), a chunk that shares too few valid pixels with the
/// others to be connected to chunk 0, and (naming both chunks) degenerate shared geometry.
ChunkAlignment align_chunks(const std::vector<PredictionChunk>& chunks, const AlignmentOptions& options = {});

}  // namespace avsplat
