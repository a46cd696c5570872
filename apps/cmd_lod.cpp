// `avsplat lod IN OUT/lod-meta.json [--levels N] [--ratio 0.5] [--node-size K] [--chunk-size C]
//  [--method merge|voxel] [--cameras C | --orbit N | --eye ...]`: a PlayCanvas LOD set from one
// scene (reduce/build_lod.h): level 0 the input, each further level the previous one simplified
// whole, cut into the octree of lod-meta.json and written as SOG chunks.
#include "camera_options.h"
#include "choice_option.h"
#include "commands.h"
#include "input_checks.h"
#include "input_formats.h"
#include "progress.h"

#include "avsplat/io/camera_json.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/reduce/build_lod.h"
#include "avsplat/reduce/names.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

namespace avsplat::cli {

namespace {

struct LodArgs {
    std::string in, out;
    CameraArgs cameras;
    int levels = BuildLodOptions{}.levels;
    double ratio = BuildLodOptions{}.ratio;
    std::size_t node_size = LodWriteOptions{}.node_size;
    std::size_t chunk_size = LodWriteOptions{}.chunk_size;
    SimplifyMethod method = BuildLodOptions{}.method;
};

void run_lod(const LodArgs& a) {
    std::vector<Camera> cameras;
    if (!a.cameras.file.empty()) cameras = read_camera_file(a.cameras.file);
    const GaussianCloud cloud = read_gaussians(a.in);
    if (a.cameras.file.empty() && has_cameras(a.cameras)) cameras = resolve_cameras(a.cameras, cloud);
    BuildLodOptions o;
    o.levels = a.levels;
    o.ratio = a.ratio;
    o.method = a.method;
    const auto t0 = std::chrono::steady_clock::now();
    LodBuild build;
    {
        // Each level costs about half the one before: the bar counts Gaussians simplified.
        std::size_t work = 0, n = cloud.size();
        for (int l = 1; a.levels ? l < a.levels : n > o.coarsest; ++l, n = std::size_t(std::llround(n * a.ratio))) work += n;
        Progress progress("lod: simplifying levels", std::max<std::size_t>(1, work));
        std::size_t last = cloud.size();
        o.progress = [&](int level, int) {
            if (level == 0) return;
            progress.advance(last, "level " + std::to_string(level));
            last = std::size_t(std::llround(last * a.ratio));
        };
        build = build_lod_levels(cloud, o, cameras);
        progress.finish();
    }
    const double simplify_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    LodWriteOptions w;
    w.node_size = a.node_size;
    w.chunk_size = a.chunk_size;
    {
        std::unique_ptr<Progress> progress;
        w.progress = [&progress](std::size_t done, std::size_t total) {
            if (!progress) progress = std::make_unique<Progress>("lod: writing SOG chunks", std::max<std::size_t>(1, total));
            if (done > 0) progress->advance(1, std::to_string(done) + "/" + std::to_string(total));
        };
        write_lod_set(a.out, build.levels, w);
        if (progress) progress->finish();
    }
    const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("lod (%s): %zu levels in %.3f s (levels %.3f s, writing %.3f s)\n", to_string(a.method).c_str(),
                build.levels.size(), total_s, simplify_s, total_s - simplify_s);
    for (std::size_t l = 0; l < build.levels.size(); ++l) {
        std::printf("  level %zu  %zu Gaussians", l, build.levels[l].size());
        if (l > 0) std::printf("  %.3f s", build.seconds[l]);
        if (l > 0 && std::isfinite(build.errors[l])) std::printf("  rendered RMSE vs level %zu %.6g", l - 1, build.errors[l]);
        std::printf("\n");
    }
    std::printf("wrote %s\n", a.out.c_str());
}

}  // namespace

void add_lod(CLI::App& app) {
    auto* cmd = app.add_subcommand("lod", "Build a PlayCanvas LOD set (lod-meta.json and SOG chunks) from a scene");
    auto a = std::make_shared<LodArgs>();
    cmd->add_option("input", a->in, "input Gaussians: " + readable_formats(false))->required()->check(existing_input());
    cmd->add_option("output", a->out, "the lod-meta.json to write; the SOG chunks go beside it (<level>_<k>/)")
        ->required()
        ->check(CLI::Validator(
            [](std::string& p) {
                return p.size() >= 5 && p.compare(p.size() - 5, 5, ".json") == 0 ? std::string()
                                                                                 : "must end in .json (lod-meta.json)";
            },
            "PATH.json"));
    cmd->add_option("--levels", a->levels,
                    "levels including level 0 (0: until the coarsest holds at most 65536 Gaussians)")
        ->check(CLI::Range(0, 64));
    cmd->add_option("--ratio", a->ratio, "each level's count over the previous one's, in (0, 1)")
        ->check(CLI::Range(0.0, 1.0));
    cmd->add_option("--node-size", a->node_size, "most Gaussians (all levels) of a tree leaf")->check(at_least_one());
    cmd->add_option("--chunk-size", a->chunk_size, "Gaussians of a level after which a new SOG chunk begins")
        ->check(at_least_one());
    add_choice(*cmd, "--method", a->method, enum_names<SimplifyMethod>(),
               "merge: pairwise moment-matching merges; voxel: occupancy fusion at a searched voxel size");
    add_camera_options(*cmd, a->cameras);
    cmd->callback([a] {
        if (!(a->ratio > 0.0 && a->ratio < 1.0)) throw CLI::ValidationError("--ratio", "must be in (0, 1)");
        run_lod(*a);
    });
}

}  // namespace avsplat::cli
