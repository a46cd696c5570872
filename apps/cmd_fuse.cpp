// `avsplat fuse INPUT... -o OUT --voxel V [--policy P] [knobs]`: voxel fusion of predictions.
//
// Inputs are Gaussian files (.ply, .splat) or prediction .npz files (prediction_npz.h); all of
// them are concatenated, in order, into one sample set and fused with one sample per occupied
// voxel (fusion.h). Gaussians (per-pixel Gaussians, point maps, Gaussian files) go through
// fuse_gaussians and are written as Gaussians (.ply, .splat). Raw features go through
// fuse_voxels and are written as an .npz, because a PLY of Gaussians has no place for an
// arbitrary feature vector and a decoder downstream wants the arrays anyway:
//   positions (M, 3) float32, features (M, C) float32, voxel_coords (M, 3) int32,
//   and the diagnostics below.
// --diagnostics D.npz writes the per-voxel diagnostics of either kind: occupancy (M,) int32,
// temperature (M,) float32, variance (M,) float32, reliability (M,) float32, kept (M,) int32,
// entropy (M,) float32, voxel_coords (M, 3) int32. A summary of them is printed.
#include "commands.h"
#include "fusion_options.h"
#include "prediction_npz.h"
#include "progress.h"

#include "avsplat/core/error.h"
#include "avsplat/fusion/fusion.h"
#include "avsplat/io/camera_json.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/npz.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat::cli {

namespace {

struct FuseArgs {
    std::vector<std::string> inputs;
    std::string output;
    std::string cameras;
    std::string diagnostics;
    double voxel = 0.0;
    FusionParams params;
};

std::string format_number(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

template <class T>
double mean_of(const std::vector<T>& v) {
    double s = 0.0;
    for (T x : v) s += static_cast<double>(x);
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
}

void print_summary(const VoxelDiagnostics& d, const FusionParams& p, std::size_t samples, std::size_t dropped,
                   double voxel, double seconds) {
    const std::size_t m = d.occupancy.size();
    std::printf("fused %zu samples into %zu voxels (voxel %g, policy %s) in %.3f s\n", samples, m, voxel,
                policy_name(p.policy), seconds);
    std::printf("  dropped invalid  %zu\n", dropped);
    if (m == 0) return;
    std::vector<std::int32_t> occ = d.occupancy;
    std::nth_element(occ.begin(), occ.begin() + static_cast<std::ptrdiff_t>(m / 2), occ.end());
    const std::size_t singles = static_cast<std::size_t>(std::count(d.occupancy.begin(), d.occupancy.end(), 1));
    std::printf("  occupancy        mean %.3g, median %d, max %d; %.1f%% of voxels hold one sample\n",
                mean_of(d.occupancy), occ[m / 2], *std::max_element(d.occupancy.begin(), d.occupancy.end()),
                100.0 * static_cast<double>(singles) / static_cast<double>(m));
    const auto [tmin, tmax] = std::minmax_element(d.temperature.begin(), d.temperature.end());
    if (std::isinf(*tmin)) std::printf("  temperature      inf (plain mean)\n");
    else std::printf("  temperature      min %.3g, mean %.3g, max %.3g\n", *tmin, mean_of(d.temperature), *tmax);
    std::printf("  variance         mean %.3g (voxel^2 = %.3g)\n", mean_of(d.variance), voxel * voxel);
    std::printf("  reliability      mean %.3g\n", mean_of(d.reliability));
    std::printf("  kept samples     %.3g per voxel (of %.3g)\n", mean_of(d.kept), mean_of(d.occupancy));
    std::printf("  weight entropy   mean %.3g nats\n", mean_of(d.entropy));
}

void write_diagnostics(const std::string& path, const VoxelDiagnostics& d, const std::vector<std::int32_t>& coords) {
    const std::size_t m = d.occupancy.size();
    write_npz(path, {NpyArray::from_data("occupancy", {m}, d.occupancy.data()),
                     NpyArray::from_data("temperature", {m}, d.temperature.data()),
                     NpyArray::from_data("variance", {m}, d.variance.data()),
                     NpyArray::from_data("reliability", {m}, d.reliability.data()),
                     NpyArray::from_data("kept", {m}, d.kept.data()),
                     NpyArray::from_data("entropy", {m}, d.entropy.data()),
                     NpyArray::from_data("voxel_coords", {m, 3}, coords.data())});
}

void run_fuse(const FuseArgs& a) {
    validate(a.params);
    if (!(a.voxel > 0.0) || !std::isfinite(a.voxel))
        throw std::invalid_argument("--voxel: must be finite and > 0, got " + format_number(a.voxel));
    const std::string out_ext = file_extension(a.output);
    if (out_ext != ".ply" && out_ext != ".splat" && out_ext != ".npz")
        throw IOError(a.output + ": unsupported output extension '" + out_ext +
                      "' (.ply or .splat for Gaussians, .npz for raw features)");
    if (!a.diagnostics.empty() && file_extension(a.diagnostics) != ".npz")
        throw IOError(a.diagnostics + ": --diagnostics writes an .npz file");
    std::vector<Camera> cameras;
    if (!a.cameras.empty()) cameras = read_cameras_json(a.cameras);

    // Read every input; they must all be Gaussians or all raw features.
    std::vector<GaussianCloud> clouds;
    std::vector<PredictionSamples> features;
    {
        Progress progress("reading inputs", a.inputs.size());
        for (const std::string& path : a.inputs) {
            if (file_extension(path) == ".npz") {
                PredictionSamples p = read_prediction_npz(path, cameras);
                progress.print(path + ": " + p.description + ", " + std::to_string(p.size()) + " samples");
                if (p.kind == PredictionSamples::Kind::Gaussians) clouds.push_back(std::move(p.gaussians));
                else features.push_back(std::move(p));
            } else {
                clouds.push_back(read_gaussians(path));
                progress.print(path + ": " + std::to_string(clouds.back().size()) + " Gaussians");
            }
            if (!clouds.empty() && !features.empty())
                throw IOError(path + ": inputs mix Gaussians and raw features; fuse one kind at a time");
            progress.advance(1, path);
        }
        progress.finish();
    }

    const auto t0 = std::chrono::steady_clock::now();
    auto seconds = [&t0] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
    if (!features.empty()) {
        if (out_ext != ".npz")
            throw IOError(a.output + ": raw features fuse to an .npz (positions, features, voxel_coords), not " + out_ext);
        const int channels = features.front().channels;
        const bool with_conf = !features.front().confidence.empty();
        std::vector<float> positions, values, confidence;
        for (std::size_t k = 0; k < features.size(); ++k) {
            const PredictionSamples& f = features[k];
            if (f.channels != channels)
                throw IOError(a.inputs[k] + ": " + std::to_string(f.channels) + " feature channels, the first input has " +
                              std::to_string(channels));
            if (f.confidence.empty() == with_conf)
                throw IOError(a.inputs[k] + ": confidence must be present in all inputs or in none");
            positions.insert(positions.end(), f.positions.begin(), f.positions.end());
            values.insert(values.end(), f.features.begin(), f.features.end());
            confidence.insert(confidence.end(), f.confidence.begin(), f.confidence.end());
        }
        const std::size_t n = positions.size() / 3;
        const FeatureFusionResult r = fuse_voxels(positions.data(), n, values.data(), channels, a.voxel,
                                                  with_conf ? confidence.data() : nullptr, a.params);
        print_summary(r.diagnostics, a.params, n, r.dropped, a.voxel, seconds());
        const std::size_t m = r.size();
        const VoxelDiagnostics& d = r.diagnostics;
        write_npz(a.output, {NpyArray::from_data("positions", {m, 3}, r.positions.data()),
                             NpyArray::from_data("features", {m, static_cast<std::size_t>(channels)}, r.features.data()),
                             NpyArray::from_data("voxel_coords", {m, 3}, r.voxel_coords.data()),
                             NpyArray::from_data("occupancy", {m}, d.occupancy.data()),
                             NpyArray::from_data("temperature", {m}, d.temperature.data()),
                             NpyArray::from_data("variance", {m}, d.variance.data()),
                             NpyArray::from_data("reliability", {m}, d.reliability.data()),
                             NpyArray::from_data("kept", {m}, d.kept.data()),
                             NpyArray::from_data("entropy", {m}, d.entropy.data())});
        if (!a.diagnostics.empty()) write_diagnostics(a.diagnostics, d, r.voxel_coords);
        std::printf("wrote %zu fused feature vectors (C = %d) to %s\n", m, channels, a.output.c_str());
        return;
    }

    if (out_ext == ".npz")
        throw IOError(a.output + ": Gaussians are written as .ply or .splat; .npz output is for raw features");
    const GaussianCloud cloud = clouds.size() == 1 ? std::move(clouds.front()) : concatenate(clouds);
    clouds.clear();
    const GaussianFusionResult r = fuse_gaussians(cloud, a.voxel, a.params);
    print_summary(r.diagnostics, a.params, cloud.size(), r.dropped, a.voxel, seconds());
    write_gaussians(a.output, r.cloud);
    if (!a.diagnostics.empty()) write_diagnostics(a.diagnostics, r.diagnostics, r.voxel_coords);
    std::printf("wrote %zu Gaussians to %s\n", r.cloud.size(), a.output.c_str());
}

}  // namespace

void add_fuse(CLI::App& app) {
    auto* cmd = app.add_subcommand(
        "fuse",
        "Voxel-fuse predictions (3DGS .ply/.splat, or prediction .npz: per-pixel Gaussians, point maps or "
        "raw features) into one sample per occupied voxel");
    auto a = std::make_shared<FuseArgs>();
    cmd->add_option("inputs", a->inputs, "input files (.ply, .splat, .npz), concatenated in order")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("-o,--output", a->output,
                    "output: .ply or .splat for Gaussians; .npz for raw features (positions, features, voxel_coords, "
                    "diagnostics)")
        ->required();
    cmd->add_option("--voxel", a->voxel, "voxel edge length, > 0 (world units)")->required();
    cmd->add_option("--cameras", a->cameras,
                    "cameras JSON, one per view: sizes point-map Gaussians by the pixel footprint (default: kNN)")
        ->check(CLI::ExistingFile);
    cmd->add_option("--diagnostics", a->diagnostics, "also write the per-voxel diagnostics to this .npz");
    add_fusion_options(*cmd, a->params);
    cmd->callback([a] { run_fuse(*a); });
}

}  // namespace avsplat::cli
