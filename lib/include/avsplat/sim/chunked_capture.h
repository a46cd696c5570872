// Simulated chunked captures: a long trajectory predicted window by window, as users run a
// feed-forward model that takes a bounded number of views per pass.
//
// The trajectory is simulate_predictions' arc with options.views frames. Windows of `window`
// frames start every window - overlap frames (the last window ends at the last frame, so it may
// overlap its neighbour more). Each window re-predicts its frames with its own errors, as a
// second model pass does: on top of the trajectory's prediction, every (window, frame) gets an
// independent misregistration (a rigid motion about the predicted camera centre, rms
// options.pose_noise_rot_deg and options.pose_noise_trans) and a depth factor 1 + depth_noise n
// per pixel; then the window is expressed in its own frame: its first true camera's coordinates
// multiplied by a scale drawn log-uniformly from [min_scale, max_scale]. Points, true points,
// normals and the cameras (predicted, true and held-out targets) are moved; the head features
// are left out (their log scales are in world units). Seeded per (seed, window, frame):
// bit-identical for a seed and any thread count.
#pragma once

#include "avsplat/registration/prediction_chunk.h"
#include "avsplat/registration/similarity.h"
#include "avsplat/sim/simulator.h"

#include <cstdint>
#include <vector>

namespace avsplat {

struct ChunkedCaptureOptions {
    int window = 32;          ///< frames per window, >= 2 and <= the frame count
    int overlap = 8;          ///< frames shared by consecutive windows, 1 .. window - 1
    double min_scale = 0.5;   ///< range of the windows' random scales, 0 < min_scale <= max_scale
    double max_scale = 2.0;
    std::uint64_t seed = 0;   ///< of the windows' errors and scales

    /// Throws std::invalid_argument naming the first field out of range.
    void validate(int frames) const;
};

struct CaptureChunk {
    Predictions predictions;               ///< the window's views, in the window's frame
    std::vector<std::int64_t> frame_ids;   ///< global frame of each view
    Similarity world_from_chunk;           ///< the true transform into the world frame

    /// The window as stitching takes it: points, valid, confidence (logit), frame ids and
    /// predictions.gaussians() (one flat Gaussian per valid pixel). `name` names it in errors.
    PredictionChunk prediction_chunk(const std::string& name = "") const;
};

struct ChunkedCapture {
    Predictions trajectory;             ///< all frames in one pass, in the world frame
    std::vector<CaptureChunk> chunks;   ///< the windows in trajectory order
};

/// Simulates the chunked capture of options.views frames (see the header comment). Throws
/// std::invalid_argument for invalid options.
ChunkedCapture simulate_chunked_capture(const SimulatorOptions& options, const ChunkedCaptureOptions& chunking = {});

}  // namespace avsplat
