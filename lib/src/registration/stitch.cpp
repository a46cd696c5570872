// Stitching: align, move every chunk into chunk 0's frame, fuse.
#include "avsplat/registration/stitch.h"

#include "avsplat/core/transform.h"
#include "avsplat/fusion/fusion_stream.h"

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace avsplat {

GaussianCloud fuse_chunks(const std::vector<PredictionChunk>& chunks, const std::vector<Similarity>& transforms,
                          double voxel_size, const FusionParams& params, const StitchOptions& options) {
    if (transforms.size() != chunks.size())
        throw std::invalid_argument("fuse_chunks: " + std::to_string(transforms.size()) + " transforms for " +
                                    std::to_string(chunks.size()) + " chunks");
    if (chunks.empty()) throw std::invalid_argument("fuse_chunks: no chunks");
    auto moved = [&](std::size_t i) {
        if (chunks[i].gaussians.size() == 0)
            throw std::invalid_argument("fuse_chunks: chunk " + std::to_string(i) + " ('" + chunks[i].name +
                                        "') has no Gaussians");
        const Similarity& T = transforms[i];
        try {
            return transform(chunks[i].gaussians, T.rotation, T.translation, T.scale);
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument("fuse_chunks: chunk " + std::to_string(i) + " ('" + chunks[i].name +
                                        "'): " + e.what());
        }
    };
    if (options.fuse && options.memory_limit > 0) {
        FusionStream stream(voxel_size, params, options.memory_limit, options.work_dir);
        for (std::size_t i = 0; i < chunks.size(); ++i) stream.add_gaussians(moved(i));
        return stream.finish_gaussians().cloud;
    }
    std::vector<GaussianCloud> all;
    all.reserve(chunks.size());
    for (std::size_t i = 0; i < chunks.size(); ++i) all.push_back(moved(i));
    GaussianCloud joined = concatenate(all);
    all.clear();
    if (!options.fuse) return joined;
    return fuse_gaussians(joined, voxel_size, params).cloud;
}

StitchResult stitch(const std::vector<PredictionChunk>& chunks, double voxel_size, const FusionParams& params,
                    const StitchOptions& options) {
    StitchResult result;
    result.alignment = align_chunks(chunks, options.alignment);
    for (const PredictionChunk& c : chunks) result.input_gaussians += c.gaussians.size();
    result.cloud = fuse_chunks(chunks, result.alignment.transforms, voxel_size, params, options);
    return result;
}

}  // namespace avsplat
