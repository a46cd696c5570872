// `avsplat render IN --camera CAM.json -o OUT.png [--depth D.png] [--alpha A.png]
//  [--backend cpu|cuda]`: renders Gaussians (.ply, .splat, or a prediction .npz) from one camera
// of a cameras JSON (io/camera_json.h) with the splat renderer (render.h) and writes 8-bit PNGs
// (io/image.h): the colour image, and optionally the turbo-coloured expected depth and the
// accumulated opacity.
#include "commands.h"
#include "input_checks.h"

#include "choice_option.h"
#include "avsplat/predictions/prediction_npz.h"

#include "avsplat/core/error.h"
#include "avsplat/core/names.h"
#include "avsplat/render/names.h"
#include "avsplat/io/camera_json.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/render/render.h"
#ifdef AVSPLAT_WITH_OPEN3D
#include "avsplat/io/image.h"
#endif

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace avsplat::cli {

namespace {

struct RenderArgs {
    std::string input;
    std::string camera;
    std::size_t camera_index = 0;
    std::string output;
    std::string depth;
    std::string alpha;
    std::vector<float> background{0.0f, 0.0f, 0.0f};
    RenderOptions options;
};

void require_png(const std::string& path, const char* option) {
    if (!path.empty() && file_extension(path) != ".png")
        throw IOError(path + ": " + option + " writes a PNG image (the name must end in .png)");
}

void run_render(const RenderArgs& a) {
#ifndef AVSPLAT_WITH_OPEN3D
    (void)a;
    throw IOError("render: PNG output needs avsplat built with Open3D (AVSPLAT_WITH_OPEN3D=ON)");
#else
    // Check the cheap things before reading and rendering, so that a typo fails at once.
    require_png(a.output, "--output");
    require_png(a.depth, "--depth");
    require_png(a.alpha, "--alpha");
    RenderOptions options = a.options;
    for (int c = 0; c < 3; ++c) options.background[static_cast<std::size_t>(c)] = a.background[static_cast<std::size_t>(c)];
    const Camera camera = read_camera_json(a.camera, a.camera_index);
    const GaussianCloud cloud = read_gaussian_input(a.input);
    const RenderResult r = render(cloud, camera, options);
    std::printf("rendered %zu Gaussians at %dx%d (%s, %s): %s\n", cloud.size(), r.width, r.height,
                to_string(options.backend).c_str(),
                to_string(options.precision).c_str(), r.stats.summary().c_str());
    write_color_png(a.output, r.color.data(), r.width, r.height);
    std::printf("wrote %s\n", a.output.c_str());
    if (!a.depth.empty()) {
        write_depth_png(a.depth, r.depth.data(), r.width, r.height);
        std::printf("wrote %s\n", a.depth.c_str());
    }
    if (!a.alpha.empty()) {
        write_alpha_png(a.alpha, r.alpha.data(), r.width, r.height);
        std::printf("wrote %s\n", a.alpha.c_str());
    }
#endif
}

}  // namespace

void add_render(CLI::App& app) {
    auto* cmd = app.add_subcommand("render", "Render Gaussians (.ply, .splat, prediction .npz) from a camera to PNG images");
    auto a = std::make_shared<RenderArgs>();
    cmd->add_option("input", a->input, "Gaussians (.ply, .splat, .npz)")->required()->check(existing_input());
    cmd->add_option("--camera", a->camera, "cameras JSON (avsplat, 3DGS cameras.json or transforms.json)")
        ->required()
        ->check(existing_input());
    cmd->add_option("--camera-index", a->camera_index, "which camera of the file")->capture_default_str();
    cmd->add_option("-o,--output", a->output, "colour image (.png)")->required();
    cmd->add_option("--depth", a->depth, "also write the expected depth, turbo-coloured (.png)");
    cmd->add_option("--alpha", a->alpha, "also write the accumulated opacity, grayscale (.png)");
    add_choice(*cmd, "--backend", a->options.backend, enum_names<Backend>(),
               "CPU renderer or CUDA renderer (needs a CUDA build and a device)");
    add_choice(*cmd, "--precision", a->options.precision,
               enum_names<Precision>(),
               "float32 (fast path) or float64 (reference)");
    cmd->add_option("--background", a->background, "background colour R,G,B in [0, 1]")
        ->delimiter(',')
        ->expected(3)
        ->capture_default_str();
    cmd->add_flag("--antialiased", a->options.antialiased, "Mip-Splatting opacity compensation (gsplat 'antialiased')");
    auto* cutoffs = "Renderer cut-offs";
    cmd->add_option("--low-pass", a->options.low_pass, "added to the 2D covariance diagonal, pixels^2")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->add_option("--alpha-threshold", a->options.alpha_threshold, "skip splats below this alpha at a pixel")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->add_option("--transmittance-stop", a->options.transmittance_stop, "stop a pixel below this transmittance")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->add_option("--extent-sigma", a->options.extent_sigma, "k of the k-sigma footprint box")
        ->capture_default_str()
        ->group(cutoffs);
    cmd->callback([a] { run_render(*a); });
}

}  // namespace avsplat::cli
