// `avsplat prune IN OUT [--cameras C | --orbit N | --eye ...] [--min-opacity O] [--min-contribution C]`: removes
// the Gaussians that cannot change an image (reduce/prune.h) and prints what was left out, by
// reason. Reads and writes every Gaussian format (io/gaussian_io.h).
#include "commands.h"
#include "progress.h"
#include "input_checks.h"
#include "input_formats.h"

#include "camera_options.h"
#include "choice_option.h"
#include "avsplat/predictions/prediction_npz.h"

#include "avsplat/core/names.h"
#include "avsplat/io/camera_json.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/reduce/prune.h"

#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace avsplat::cli {

namespace {

struct PruneArgs {
    std::string input;
    std::string output;
    CameraArgs cameras;
    float min_contribution = 0.0f;
    bool has_min_contribution = false;  // unset: the exact rule
    PruneParams params;
};

void run_prune(PruneArgs a) {
    std::vector<Camera> cameras;
    if (!a.cameras.file.empty()) cameras = read_camera_file(a.cameras.file);
    if (a.has_min_contribution) a.params.min_contribution = a.min_contribution;
    const GaussianCloud cloud = read_gaussian_input(a.input);
    // Without cameras prune removes only what no view can show; an orbit or a look-at must be asked for.
    if (a.cameras.file.empty() && has_cameras(a.cameras)) cameras = resolve_cameras(a.cameras, cloud);
    Progress progress("prune: cameras rendered", std::max<std::size_t>(cameras.size(), 1));  // on a terminal only
    PruneResult r;
    {
        const auto following = progress.follow();
        r = prune(cloud, cameras, a.params);
    }
    progress.finish();
    std::printf("prune: %s\n", r.summary().c_str());
    if (r.invisible > 0 && a.params.min_contribution)
        std::printf("prune: largest contribution removed %.6g (min_contribution %.6g)\n", r.max_removed_contribution,
                    double(*a.params.min_contribution));
    write_gaussians(a.output, r.cloud);
    std::printf("wrote %zu Gaussians to %s\n", r.cloud.size(), a.output.c_str());
}

}  // namespace

void add_prune(CLI::App& app) {
    auto* cmd = app.add_subcommand(
        "prune", "Remove Gaussians that cannot change an image: invalid, below --min-opacity, or (with cameras: --cameras, --orbit or --eye) "
                 "composited by no pixel of any camera");
    auto a = std::make_shared<PruneArgs>();
    cmd->add_option("input", a->input, "input Gaussians: " + readable_formats(true))
        ->required()
        ->check(existing_input());
    cmd->add_option("output", a->output, "output Gaussians (format from the name)")->required();
    add_camera_options(*cmd, a->cameras);
    cmd->add_option("--min-opacity", a->params.min_opacity, "remove opacity below this, in [0, 1]")
        ->capture_default_str();
    auto* min_contribution = cmd->add_option("--min-contribution", a->min_contribution,
                    "with cameras: remove Gaussians whose alpha T stays below this at every pixel (bounded, not "
                    "exact: see reduce/prune.h); default: only those with none");
    add_choice(*cmd, "--precision", a->params.render.precision, enum_names<Precision>(),
               "precision of the renders that measure the contributions");
    cmd->add_flag("--antialiased", a->params.render.antialiased, "renders with Mip-Splatting opacity compensation");
    auto* cutoffs = "Renderer cut-offs (use those the pruned scene is rendered with)";
    cmd->add_option("--low-pass", a->params.render.low_pass, "added to the 2D covariance diagonal, pixels^2")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->add_option("--alpha-threshold", a->params.render.alpha_threshold, "skip splats below this alpha at a pixel")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->add_option("--transmittance-stop", a->params.render.transmittance_stop,
                    "stop a pixel below this transmittance")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->add_option("--extent-sigma", a->params.render.extent_sigma, "k of the k-sigma footprint box")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->callback([a, min_contribution] {
        a->has_min_contribution = min_contribution->count() > 0;
        run_prune(*a);
    });
}

}  // namespace avsplat::cli
