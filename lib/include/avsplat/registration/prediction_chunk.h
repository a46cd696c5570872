// One window of a long capture as the model predicted it: S views of H x W pixels in the
// window's own coordinate frame and scale, which global frame each view is, and the Gaussians
// to stitch. Read from the prediction .npz layout (predictions/prediction_npz.h) plus an
// integer array `frame_ids` (S values).
#pragma once

#include "avsplat/core/confidence.h"
#include "avsplat/core/gaussians.h"

#include <cstdint>
#include <string>
#include <vector>

namespace avsplat {

struct PredictionChunk {
    /// Names the chunk in error messages (a file name, or "chunk 3").
    std::string name;
    int views = 0;
    int height = 0;
    int width = 0;
    std::vector<std::int64_t> frame_ids;  ///< S global frame indices, distinct
    std::vector<float> points;            ///< S x H x W x 3 positions in the chunk's frame
    std::vector<std::uint8_t> valid;      ///< S x H x W (non-zero: predicted), or empty: all
    std::vector<float> confidence;        ///< S x H x W, or empty: every pixel weighs 1
    ConfidenceMapping confidence_mapping = ConfidenceMapping::Logit;
    /// The Gaussians to stitch, in the chunk's frame (any count; usually one per valid pixel).
    /// Empty for alignment only.
    GaussianCloud gaussians;

    /// Throws std::invalid_argument naming the chunk and the field: dimensions not > 0, array
    /// sizes that do not match them, repeated frame ids, a non-finite point at a valid pixel
    /// (with its view, row, col), a confidence outside the mapping's domain, or no valid pixel.
    void validate() const;
};

/// Reads a prediction .npz (predictions/prediction_npz.h: points S x H x W x 3, valid,
/// confidence, the Gaussian arrays) and its frame_ids (S integers). The chunk's name is the
/// path. Throws avsplat::IOError naming the file and the array.
PredictionChunk read_prediction_chunk(const std::string& path,
                                      ConfidenceMapping mapping = ConfidenceMapping::Logit);

}  // namespace avsplat
