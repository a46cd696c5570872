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
//
// Out of core: when the inputs' total size on disk exceeds --memory-limit (default a quarter of
// the machine's memory), the inputs are read one at a time into a FusionStream (fusion_stream.h)
// that spills them by blocks of voxel keys to a work folder and fuses block by block; the result
// is the same, bit for bit. (One input file must still fit in memory.) Outputs are written to a
// hidden file beside the destination and renamed into place, so an interrupted run never leaves
// a partial file under the destination's name.
#include "commands.h"
#include "input_checks.h"
#include "input_formats.h"
#include "fusion_options.h"
#include "avsplat/predictions/prediction_npz.h"
#include "progress.h"

#include "avsplat/core/error.h"
#include "avsplat/core/names.h"
#include "avsplat/fusion/fusion_knobs.h"
#include "avsplat/fusion/names.h"
#include "avsplat/fusion/fusion.h"
#include "avsplat/fusion/fusion_stream.h"
#include "avsplat/io/camera_json.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/npz.h"
#include "avsplat/io/ply.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

namespace avsplat::cli {

namespace {

struct FuseArgs {
    std::vector<std::string> inputs;
    std::string output;
    std::string cameras;
    std::string diagnostics;
    double voxel = 0.0;
    FusionParams params;
    std::string memory_limit;  // bytes, with an optional K, M, G or T suffix; "" : default
    std::string scheduler;     // Dask scheduler address; "" : fuse here
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

// Calls write(tmp) on a hidden file beside `path`, then renames it to `path`; the hidden file is
// removed when write throws. Error messages name `path`.
void write_atomically(const std::string& path, const std::function<void(const std::string&)>& write) {
    const std::filesystem::path dest(path);
    const std::string tmp =
        (dest.parent_path() / (".partial-" + std::to_string(::getpid()) + "-" + dest.filename().string())).string();
    try {
        write(tmp);
        std::filesystem::rename(tmp, dest);
    } catch (const IOError& e) {
        std::error_code ec;
        std::filesystem::remove(tmp, ec);
        std::string what = e.what();
        for (std::size_t at = what.find(tmp); at != std::string::npos; at = what.find(tmp, at + path.size()))
            what.replace(at, tmp.size(), path);
        throw IOError(what);
    } catch (const std::filesystem::filesystem_error& e) {
        std::error_code ec;
        std::filesystem::remove(tmp, ec);
        throw IOError(path + ": cannot write: " + e.code().message());
    } catch (...) {
        std::error_code ec;
        std::filesystem::remove(tmp, ec);
        throw;
    }
}

void write_feature_output(const FuseArgs& a, const FeatureFusionResult& r, std::size_t samples, double seconds) {
    print_summary(r.diagnostics, a.params, samples, r.dropped, a.voxel, seconds);
    const std::size_t m = r.size();
    const VoxelDiagnostics& d = r.diagnostics;
    write_atomically(a.output, [&](const std::string& path) {
        write_npz(path, {NpyArray::from_data("positions", {m, 3}, r.positions.data()),
                         NpyArray::from_data("features", {m, static_cast<std::size_t>(r.channels)}, r.features.data()),
                         NpyArray::from_data("voxel_coords", {m, 3}, r.voxel_coords.data()),
                         NpyArray::from_data("occupancy", {m}, d.occupancy.data()),
                         NpyArray::from_data("temperature", {m}, d.temperature.data()),
                         NpyArray::from_data("variance", {m}, d.variance.data()),
                         NpyArray::from_data("reliability", {m}, d.reliability.data()),
                         NpyArray::from_data("kept", {m}, d.kept.data()),
                         NpyArray::from_data("entropy", {m}, d.entropy.data())});
    });
    if (!a.diagnostics.empty())
        write_atomically(a.diagnostics, [&](const std::string& path) { write_diagnostics(path, d, r.voxel_coords); });
    std::printf("wrote %zu fused feature vectors (C = %d) to %s\n", m, r.channels, a.output.c_str());
}

void write_gaussian_output(const FuseArgs& a, const GaussianFusionResult& r, std::size_t samples, double seconds) {
    print_summary(r.diagnostics, a.params, samples, r.dropped, a.voxel, seconds);
    write_atomically(a.output, [&](const std::string& path) { write_gaussians(path, r.cloud); });
    if (!a.diagnostics.empty())
        write_atomically(a.diagnostics,
                         [&](const std::string& path) { write_diagnostics(path, r.diagnostics, r.voxel_coords); });
    std::printf("wrote %zu Gaussians to %s\n", r.cloud.size(), a.output.c_str());
}

// One input file, decoded: Gaussians (a Gaussian file, or per-pixel Gaussians / point maps in a
// prediction .npz) or raw features (a prediction .npz). A value error while reading (a NaN point
// handed to gaussians_from_point_maps) names the file.
// Models write the pixels they did not predict as (0, 0, 0); without a `valid` array they would
// be fused as real points, piling up at the origin. Exact zeros are rare in real predictions.
void warn_samples_at_origin(const std::string& path, const PredictionSamples& p) {
    const float* xyz = p.kind == PredictionSamples::Kind::Gaussians ? p.gaussians.means.data() : p.positions.data();
    std::size_t at_origin = 0;
    for (std::size_t i = 0; i < p.size(); ++i)
        at_origin += xyz[3 * i] == 0.0f && xyz[3 * i + 1] == 0.0f && xyz[3 * i + 2] == 0.0f;
    if (at_origin > 1)
        std::fprintf(stderr,
                     "avsplat: warning: %s: %zu samples lie exactly at (0, 0, 0), as pixels a model did not predict "
                     "do; mark those pixels false in a `valid` array or they are fused as points\n",
                     path.c_str(), at_origin);
}

PredictionSamples load_input(const std::string& path, const std::vector<Camera>& cameras) {
    try {
        if (file_extension(path) == ".npz") {
            PredictionSamples p = read_prediction_npz(path, cameras);
            warn_samples_at_origin(path, p);
            return p;
        }
        PredictionSamples p;
        p.kind = PredictionSamples::Kind::Gaussians;
        p.gaussians = read_gaussians(path);
        p.description = std::to_string(p.gaussians.size()) + " Gaussians";
        return p;
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(path + ": " + e.what());
    }
}

// A value error from fusion (a NaN scale, a confidence outside its mapping, a point whose voxel
// key does not fit) names an index into the concatenation of all inputs. Name the file instead:
// each input is fused on its own (on this error path only; one input at a time, read again) and
// the first that fails is reported with its own message, whose index is then local to the file.
[[noreturn]] void rethrow_naming_input(const FuseArgs& a, const std::vector<Camera>& cameras,
                                       const std::invalid_argument& error) {
    if (a.inputs.size() == 1) throw std::invalid_argument(a.inputs.front() + ": " + error.what());
    for (const std::string& path : a.inputs) {
        const PredictionSamples p = load_input(path, cameras);
        try {
            if (p.kind == PredictionSamples::Kind::Gaussians)
                fuse_gaussians(p.gaussians, a.voxel, a.params);
            else
                fuse_voxels(p.positions.data(), p.size(), p.features.data(), p.channels, a.voxel,
                            p.confidence.empty() ? nullptr : p.confidence.data(), a.params);
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument(path + ": " + e.what());
        }
    }
    throw error;  // no input fails alone (the inputs disagree with each other): the message as it was
}

std::size_t decoded_bytes(const PredictionSamples& p) {
    if (p.kind == PredictionSamples::Kind::Features)
        return 4 * (p.positions.size() + p.features.size() + p.confidence.size());
    const GaussianCloud& c = p.gaussians;
    std::size_t floats = c.means.size() + c.scales.size() + c.rotations.size() + c.opacities.size() + c.sh.size() +
                         c.confidence.size();
    for (const auto& e : c.extras) floats += e.values.size();
    return 4 * floats;
}

// Feeds one decoded input to the stream.
void add_to_stream(FusionStream& stream, const PredictionSamples& p) {
    if (p.kind == PredictionSamples::Kind::Gaussians) {
        stream.add_gaussians(p.gaussians);
    } else {
        stream.add(p.positions.data(), p.size(), p.features.data(), p.channels,
                   p.confidence.empty() ? nullptr : p.confidence.data());
    }
}

// The out-of-core ending: fuses what was added to `stream` block by block and writes the output.
void finish_streaming(const FuseArgs& a, FusionStream& stream, bool features, std::size_t limit,
                      const std::string& out_ext) {
    const auto t0 = std::chrono::steady_clock::now();
    std::printf("spilled %zu samples to %zu blocks (%.3g MB) under a memory limit of %.3g MB\n", stream.num_samples(),
                stream.num_blocks(), double(stream.spilled_bytes()) / 1e6, double(limit) / 1e6);
    auto seconds = [&t0] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
    const std::size_t n = stream.num_samples();
    Progress progress("fusing blocks", std::max<std::size_t>(n, 1));
    std::size_t shown = 0;
    stream.set_progress([&](std::size_t done, std::size_t) {
        progress.advance(done - shown);
        shown = done;
    });
    if (features) {
        if (out_ext != ".npz")
            throw IOError(a.output + ": raw features fuse to an .npz (positions, features, voxel_coords), not " + out_ext);
        FeatureFusionResult r = stream.finish();
        progress.finish();
        write_feature_output(a, r, n, seconds());
        return;
    }
    if (out_ext == ".npz")
        throw IOError(a.output + ": Gaussians are written as .ply or .splat (or .compressed.ply, .spz, .sog); .npz output is for raw features");
    if (out_ext != ".ply") {
        GaussianFusionResult r = stream.finish_gaussians();
        progress.finish();
        write_gaussian_output(a, r, n, seconds());
        return;
    }
    // PLY is written block by block as the blocks are fused: the fused cloud is never held whole
    // (only the per-voxel diagnostics and keys, for the summary and --diagnostics).
    GaussianPlyWriter out(a.output);
    GaussianFusionResult kept;
    GaussianFusionResult r = stream.finish_gaussians([&](GaussianFusionResult&& block) {
        out.append(block.cloud);
        kept.voxel_coords.insert(kept.voxel_coords.end(), block.voxel_coords.begin(), block.voxel_coords.end());
        kept.diagnostics.append(block.diagnostics);
    });
    progress.finish();
    print_summary(kept.diagnostics, a.params, n, r.dropped, a.voxel, seconds());
    out.commit();
    if (!a.diagnostics.empty())
        write_atomically(a.diagnostics,
                         [&](const std::string& path) { write_diagnostics(path, kept.diagnostics, kept.voxel_coords); });
    std::printf("wrote %zu Gaussians to %s (block by block)\n", out.size(), a.output.c_str());
}

// --scheduler: replaces this process by `python3 -m avsplat.dask` (avsplat/dask.py; $AVSPLAT_PYTHON
// names another interpreter), which fuses raw-feature .npz inputs or Gaussian files on the Dask
// cluster at that address with the same knobs. Python names of the knobs are the FusionParams
// field names. Returns only by throwing.
[[noreturn]] void exec_dask(const FuseArgs& a) {
    const FusionParams& p = a.params;
    const char* python = std::getenv("AVSPLAT_PYTHON");
    std::vector<std::string> args{python && *python ? python : "python3", "-m", "avsplat.dask", "--scheduler", a.scheduler, "-o", a.output,
                                  "--voxel", format_number(a.voxel), "--policy", policy_name(p.policy)};
    auto knob = [&args](const std::string& name, const std::string& value) {
        args.push_back("--knob");
        args.push_back(name + "=" + value);
    };
    // Every knob but the policy, by the knob table; shape applies to Gaussian inputs only, and
    // python3 -m avsplat.dask leaves it out for features.
    for (const FusionKnob& k : fusion_knobs())
        if (k.name != "policy") knob(k.name, k.get(p));
    for (const std::string& in : a.inputs) args.push_back(in);
    std::vector<char*> argv;
    for (std::string& s : args) argv.push_back(s.data());
    argv.push_back(nullptr);
    std::fflush(stdout);
    ::execvp(argv[0], argv.data());
    throw IOError(std::string("--scheduler: cannot run python3 -m avsplat.dask: ") + std::strerror(errno));
}

void fuse_inputs(const FuseArgs& a, const std::vector<Camera>& cameras, std::size_t limit, const std::string& out_ext);

void run_fuse(const FuseArgs& a) {
    validate(a.params);
    if (!(a.voxel > 0.0) || !std::isfinite(a.voxel))
        throw std::invalid_argument("--voxel: must be finite and > 0, got " + format_number(a.voxel));
    const std::string out_ext = file_extension(a.output);
    if (out_ext != ".npz") gaussian_format_for_name(a.output);  // IOError naming the formats for other names
    if (!a.diagnostics.empty() && file_extension(a.diagnostics) != ".npz")
        throw IOError(a.diagnostics + ": --diagnostics writes an .npz file");
    if (!a.scheduler.empty()) exec_dask(a);
    std::vector<Camera> cameras;
    if (!a.cameras.empty()) cameras = read_cameras_json(a.cameras);
    const std::size_t limit = parse_memory_limit(a.memory_limit);
    try {
        fuse_inputs(a, cameras, limit, out_ext);
    } catch (const std::invalid_argument& e) {
        // Reading errors name their file already; a fusion error (in memory or when a chunk
        // enters the stream) names an index, and the file is found by fusing each alone.
        const std::string what = e.what();
        for (const std::string& path : a.inputs)
            if (what.compare(0, path.size() + 2, path + ": ") == 0) throw;
        rethrow_naming_input(a, cameras, e);
    }
}

// Reads the inputs and fuses them, in memory or out of core (see run_fuse).
void fuse_inputs(const FuseArgs& a, const std::vector<Camera>& cameras, std::size_t limit,
                 const std::string& out_ext) {
    // Inputs are read one at a time and held while their decoded size stays within the limit;
    // past it they all go to a FusionStream (out of core), which gives the same result. The
    // decoded size decides, not the size on disk (a compressed .npz decodes to far more).
    std::vector<PredictionSamples> held;
    std::size_t held_bytes = 0;
    std::unique_ptr<FusionStream> stream;
    struct Schema {  // of the first input; every input must match it
        PredictionSamples::Kind kind;
        int channels;
        bool confidence;
        std::string path;
        std::vector<std::string> extras;  // of Gaussians
    };
    auto extra_names = [](const GaussianCloud& c) {
        std::vector<std::string> names;
        for (const auto& e : c.extras) names.push_back(e.name);
        return names;
    };
    auto join = [](const std::vector<std::string>& names) {
        std::string s;
        for (const auto& n : names) s += (s.empty() ? "" : " ") + n;
        return names.empty() ? std::string("none") : s;
    };
    std::optional<Schema> schema;
    {
        Progress progress("reading inputs", a.inputs.size());
        for (const std::string& path : a.inputs) {
            PredictionSamples p = load_input(path, cameras);
            progress.print(path + ": " + p.description + (p.kind == PredictionSamples::Kind::Features
                                                              ? ", " + std::to_string(p.size()) + " samples"
                                                              : std::string()));
            const bool gaussians = p.kind == PredictionSamples::Kind::Gaussians;
            if (!schema)
                schema = Schema{p.kind, p.channels,
                                gaussians ? p.gaussians.has_confidence() : !p.confidence.empty(), path,
                                gaussians ? extra_names(p.gaussians) : std::vector<std::string>{}};
            if (p.kind != schema->kind)
                throw IOError(path + ": inputs mix Gaussians and raw features; fuse one kind at a time");
            if (p.kind == PredictionSamples::Kind::Features && p.channels != schema->channels)
                throw IOError(path + ": " + std::to_string(p.channels) + " feature channels, the first input has " +
                              std::to_string(schema->channels));
            if (p.kind == PredictionSamples::Kind::Features && p.confidence.empty() == schema->confidence)
                throw IOError(path + ": confidence must be present in all inputs or in none");
            // Concatenated Gaussians must carry the same channels; say which files differ.
            if (gaussians && p.kind == schema->kind && p.gaussians.has_confidence() != schema->confidence)
                throw IOError(path + (schema->confidence ? ": has no confidence, " : ": has confidence, ") +
                              schema->path + (schema->confidence ? " has" : " does not") +
                              "; fuse inputs that all have confidence or none");
            if (gaussians && p.kind == schema->kind && extra_names(p.gaussians) != schema->extras)
                throw IOError(path + ": extra channels (" + join(extra_names(p.gaussians)) + ") differ from those of " +
                              schema->path + " (" + join(schema->extras) + "); fuse inputs with the same channels");
            if (stream) {
                add_to_stream(*stream, p);
            } else {
                held_bytes += decoded_bytes(p);
                held.push_back(std::move(p));
                if (held_bytes > limit) {
                    progress.print("the inputs exceed the memory limit (" + format_number(double(limit) / 1e6) +
                                   " MB): fusing out of core");
                    stream = std::make_unique<FusionStream>(a.voxel, a.params, limit);
                    for (const PredictionSamples& h : held) add_to_stream(*stream, h);
                    held.clear();
                    held.shrink_to_fit();
                }
            }
            progress.advance(1, path);
        }
        progress.finish();
    }
    const bool features = schema && schema->kind == PredictionSamples::Kind::Features;
    if (stream) {
        finish_streaming(a, *stream, features, limit, out_ext);
        return;
    }

    const auto t0 = std::chrono::steady_clock::now();
    auto seconds = [&t0] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
    if (features) {
        if (out_ext != ".npz")
            throw IOError(a.output + ": raw features fuse to an .npz (positions, features, voxel_coords), not " + out_ext);
        const int channels = schema->channels;
        const bool with_conf = schema->confidence;
        std::vector<float> positions, values, confidence;
        for (const PredictionSamples& f : held) {
            positions.insert(positions.end(), f.positions.begin(), f.positions.end());
            values.insert(values.end(), f.features.begin(), f.features.end());
            confidence.insert(confidence.end(), f.confidence.begin(), f.confidence.end());
        }
        held.clear();
        const std::size_t n = positions.size() / 3;
        FeatureFusionResult r;
        {
            Progress progress("fusing samples", n);
            const auto following = progress.follow();
            r = fuse_voxels(positions.data(), n, values.data(), channels, a.voxel,
                            with_conf ? confidence.data() : nullptr, a.params);
        }
        write_feature_output(a, r, n, seconds());
        return;
    }

    if (out_ext == ".npz")
        throw IOError(a.output + ": Gaussians are written as .ply or .splat (or .compressed.ply, .spz, .sog); .npz output is for raw features");
    std::vector<GaussianCloud> clouds;
    for (PredictionSamples& p : held) clouds.push_back(std::move(p.gaussians));
    held.clear();
    const GaussianCloud cloud = clouds.size() == 1 ? std::move(clouds.front()) : concatenate(clouds);
    clouds.clear();
    // Fuse before reading the clock: the order in which a call's arguments are evaluated is unspecified.
    GaussianFusionResult r;
    {
        Progress progress("fusing samples", cloud.size());
        const auto following = progress.follow();
        r = fuse_gaussians(cloud, a.voxel, a.params);
    }
    write_gaussian_output(a, r, cloud.size(), seconds());
}

}  // namespace

void add_fuse(CLI::App& app) {
    auto* cmd = app.add_subcommand(
        "fuse",
        "Voxel-fuse predictions (Gaussian files or prediction .npz) into one sample per occupied voxel");
    auto a = std::make_shared<FuseArgs>();
    cmd->add_option("inputs", a->inputs,
                    "input files, concatenated in order: " + readable_formats(false) +
                        "; or prediction .npz (per-pixel Gaussians, point maps or raw features). In an .npz, "
                        "`points` (S, H, W, 3) is required and `valid` (S, H, W) marks the predicted pixels: "
                        "without it every pixel is fused, and a warning counts the samples at exactly (0, 0, 0)")
        ->required()
        ->check(existing_input());
    cmd->add_option("-o,--output", a->output,
                    "output: a Gaussian file by name (.ply, .compressed.ply, .splat, .spz, .sog); .npz for raw features (positions, features, voxel_coords, "
                    "diagnostics)")
        ->required();
    cmd->add_option("--voxel", a->voxel, "voxel edge length, > 0 (world units)")->required();
    cmd->add_option("--cameras", a->cameras,
                    "cameras JSON, one per view: sizes point-map Gaussians by the pixel footprint (default: kNN)")
        ->check(existing_input());
    cmd->add_option("--diagnostics", a->diagnostics, "also write the per-voxel diagnostics to this .npz");
    cmd->add_option("--memory-limit", a->memory_limit,
                    "bytes (suffix K, M, G, T) the inputs may take in memory; larger inputs are fused out of core "
                    "by blocks of voxel keys, with the same result (default: a quarter of the machine's memory)");
    cmd->add_option("--scheduler", a->scheduler,
                    "fuse on the Dask cluster at this scheduler address (e.g. tcp://10.0.0.5:8786) through "
                    "python3 -m avsplat.dask: raw-feature .npz inputs to an .npz, or Gaussian files to a Gaussian file");
    add_fusion_options(*cmd, a->params);
    cmd->callback([a] { run_fuse(*a); });
}

}  // namespace avsplat::cli
