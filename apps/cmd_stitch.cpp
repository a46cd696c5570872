// `avsplat stitch CHUNK.npz... -o scene.ply --voxel V`: aligns the chunks of a long capture by
// the frames they share, moves them into the first chunk's frame and fuses them
// (registration/stitch.h); writes the scene and, beside it (scene.transforms.json), every
// chunk's transform and residual and every pair's estimate.
#include "commands.h"
#include "fusion_options.h"
#include "input_checks.h"
#include "progress.h"

#include "avsplat/io/atomic_file.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/registration/stitch.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace avsplat::cli {

namespace {

struct StitchArgs {
    std::vector<std::string> inputs;
    std::string output;
    double voxel = 0.0;
    std::string memory_limit;
    bool chain = false;
    double loss_scale = RobustFitOptions{}.loss_scale;
    FusionParams params;
};

nlohmann::json to_json(const Similarity& T) {
    nlohmann::json j;
    j["rotation"] = {{T.rotation(0, 0), T.rotation(0, 1), T.rotation(0, 2)},
                     {T.rotation(1, 0), T.rotation(1, 1), T.rotation(1, 2)},
                     {T.rotation(2, 0), T.rotation(2, 1), T.rotation(2, 2)}};
    j["translation"] = {T.translation[0], T.translation[1], T.translation[2]};
    j["scale"] = T.scale;
    return j;
}

// scene.ply -> scene.transforms.json
std::string transforms_path(const std::string& output) {
    std::filesystem::path p(output);
    p.replace_extension(".transforms.json");
    return p.string();
}

void run_stitch(const StitchArgs& a) {
    if (a.inputs.size() < 2) throw std::invalid_argument("stitch: give at least two chunks");
    const auto start = std::chrono::steady_clock::now();
    // The fusion's --confidence-mapping also turns confidences into correspondence weights.
    const ConfidenceMapping mapping = a.params.confidence_mapping;
    std::vector<PredictionChunk> chunks;
    {
        Progress progress("reading chunks", a.inputs.size());
        for (const std::string& path : a.inputs) {
            chunks.push_back(read_prediction_chunk(path, mapping));
            progress.advance(1, path);
        }
    }
    StitchOptions o;
    o.alignment.pose_graph = !a.chain;
    o.alignment.fit.loss_scale = a.loss_scale;
    if (!a.memory_limit.empty()) o.memory_limit = parse_memory_limit(a.memory_limit);
    const StitchResult r = stitch(chunks, a.voxel, a.params, o);
    write_gaussians(a.output, r.cloud);

    nlohmann::json j;
    j["reference"] = a.inputs[0];
    j["pose_graph"] = !a.chain;
    j["initial_cost"] = r.alignment.initial_cost;
    j["final_cost"] = r.alignment.final_cost;
    for (std::size_t i = 0; i < chunks.size(); ++i) {
        nlohmann::json c = to_json(r.alignment.transforms[i]);
        c["file"] = a.inputs[i];
        c["residual"] = r.alignment.residuals[i];
        c["gaussians"] = chunks[i].gaussians.size();
        j["chunks"].push_back(c);
    }
    for (const PairAlignment& p : r.alignment.pairs) {
        nlohmann::json q = to_json(p.a_from_b);
        q["a"] = p.a;
        q["b"] = p.b;
        q["correspondences"] = p.correspondences;
        q["rms_residual"] = p.rms_residual;
        q["aligned_rms"] = p.aligned_rms;
        j["pairs"].push_back(q);
    }
    const std::string json_path = transforms_path(a.output);
    write_file_atomically(json_path, j.dump(2) + "\n");
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    double worst = 0.0;
    for (double v : r.alignment.residuals) worst = std::max(worst, v);
    std::printf("stitch: %zu chunks, %zu pairs, largest chunk residual %.4g (first chunk's units)\n", chunks.size(),
                r.alignment.pairs.size(), worst);
    std::printf("wrote %zu Gaussians (from %zu) to %s and the transforms to %s in %.2f s\n", r.cloud.size(),
                r.input_gaussians, a.output.c_str(), json_path.c_str(), seconds);
}

}  // namespace

void add_stitch(CLI::App& app) {
    auto* cmd = app.add_subcommand(
        "stitch", "Align prediction chunks of a long capture by their shared frames (robust Umeyama per pair, a "
                  "pose graph over similarities) and fuse them into one scene in the first chunk's frame");
    auto a = std::make_shared<StitchArgs>();
    cmd->add_option("chunks", a->inputs,
                    "prediction .npz files with point maps (points S x H x W x 3) and frame_ids (S integers)")
        ->required()
        ->check(existing_input());
    cmd->add_option("-o,--output", a->output, "output Gaussians (format from the name); the transforms go to "
                                              "NAME.transforms.json beside it")
        ->required();
    cmd->add_option("--voxel", a->voxel, "voxel edge length, > 0 (the first chunk's units)")->required();
    cmd->add_option("--memory-limit", a->memory_limit,
                    "fuse out of core through a stream with this many bytes in memory (suffix K, M, G, T); "
                    "default: in memory");
    cmd->add_option("--loss-scale", a->loss_scale,
                    "Cauchy constant of the robust fit, as a fraction of the shared points' spread (0: least squares)")
        ->capture_default_str();
    cmd->add_flag("--chain", a->chain, "chain the pairwise estimates instead of solving the pose graph");
    add_fusion_options(*cmd, a->params);
    cmd->callback([a] { run_stitch(*a); });
}

}  // namespace avsplat::cli
