// PredictionChunk checks and the .npz reader of a chunk.
#include "avsplat/registration/prediction_chunk.h"

#include "avsplat/core/error.h"
#include "avsplat/io/npz.h"
#include "avsplat/predictions/prediction_npz.h"
#include "core/confidence_mapping.h"

#include <cmath>
#include <set>
#include <stdexcept>
#include <string>

namespace avsplat {

void PredictionChunk::validate() const {
    const std::string at = "chunk '" + name + "'";
    if (views <= 0 || height <= 0 || width <= 0)
        throw std::invalid_argument(at + ": views, height and width must be > 0 (got " + std::to_string(views) + " x " +
                                    std::to_string(height) + " x " + std::to_string(width) + ")");
    const std::size_t pixels = std::size_t(views) * height * width;
    if (frame_ids.size() != std::size_t(views))
        throw std::invalid_argument(at + ": frame_ids has " + std::to_string(frame_ids.size()) + " values for " +
                                    std::to_string(views) + " views");
    if (points.size() != 3 * pixels)
        throw std::invalid_argument(at + ": points has " + std::to_string(points.size()) + " values, expected " +
                                    std::to_string(3 * pixels) + " (views x height x width x 3)");
    if (!valid.empty() && valid.size() != pixels)
        throw std::invalid_argument(at + ": valid has " + std::to_string(valid.size()) + " values, expected " +
                                    std::to_string(pixels));
    if (!confidence.empty() && confidence.size() != pixels)
        throw std::invalid_argument(at + ": confidence has " + std::to_string(confidence.size()) + " values, expected " +
                                    std::to_string(pixels));
    std::set<std::int64_t> seen;
    for (int s = 0; s < views; ++s)
        if (!seen.insert(frame_ids[s]).second)
            throw std::invalid_argument(at + ": frame_ids[" + std::to_string(s) + "] = " + std::to_string(frame_ids[s]) +
                                        " repeats an earlier view's frame");
    std::size_t count = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
        if (!valid.empty() && !valid[i]) continue;
        const auto where = [&] {
            const std::size_t s = i / (std::size_t(height) * width), r = i / width % height, c = i % width;
            return " at pixel " + std::to_string(i) + " (view " + std::to_string(s) + ", row " + std::to_string(r) +
                   ", col " + std::to_string(c) + ")";
        };
        for (int c = 0; c < 3; ++c)
            if (!std::isfinite(points[3 * i + c])) throw std::invalid_argument(at + ": points is not finite" + where());
        if (!confidence.empty() && !confidence::confidence_valid(confidence[i], confidence_mapping))
            throw std::invalid_argument(at + ": confidence is outside its mapping's domain" + where());
        ++count;
    }
    if (count == 0) throw std::invalid_argument(at + ": no valid pixel");
}

PredictionChunk read_prediction_chunk(const std::string& path, ConfidenceMapping mapping) {
    const std::vector<NpyArray> arrays = read_npz(path);
    PredictionChunk chunk;
    chunk.name = path;
    chunk.confidence_mapping = mapping;
    const NpyArray* points = find_array(arrays, "points");
    if (!points) throw IOError(path + ": no array 'points'");
    if (points->shape.size() != 4 || points->shape[3] != 3)
        throw IOError(path + ": array 'points' has shape " + points->shape_string() +
                      ", expected (S, H, W, 3) point maps to align");
    chunk.views = static_cast<int>(points->shape[0]);
    chunk.height = static_cast<int>(points->shape[1]);
    chunk.width = static_cast<int>(points->shape[2]);
    const std::size_t pixels = points->size() / 3;
    chunk.points = points->to_float32();
    const NpyArray* ids = find_array(arrays, "frame_ids");
    if (!ids) throw IOError(path + ": no array 'frame_ids' (one global frame index per view) to align by");
    if (ids->shape.size() != 1 || ids->shape[0] != points->shape[0])
        throw IOError(path + ": array 'frame_ids' has shape " + ids->shape_string() + ", expected (" +
                      std::to_string(chunk.views) + ",)");
    for (double v : ids->to_float64()) {
        if (!(std::isfinite(v) && v == std::floor(v) && std::abs(v) < 9e15))
            throw IOError(path + ": array 'frame_ids' must hold integers");
        chunk.frame_ids.push_back(static_cast<std::int64_t>(v));
    }
    if (const NpyArray* valid = find_array(arrays, "valid")) {
        if (valid->size() != pixels)
            throw IOError(path + ": array 'valid' has shape " + valid->shape_string() + ", expected (S, H, W)");
        for (float v : valid->to_float32()) chunk.valid.push_back(v != 0.f);
    }
    if (const NpyArray* conf = find_array(arrays, "confidence")) {
        if (conf->size() != pixels)
            throw IOError(path + ": array 'confidence' has shape " + conf->shape_string() + ", expected (S, H, W)");
        chunk.confidence = conf->to_float32();
    }
    try {
        chunk.validate();
    } catch (const std::invalid_argument& e) {
        throw IOError(e.what());
    }
    chunk.gaussians = read_gaussian_input(path);
    return chunk;
}

}  // namespace avsplat
