// `avsplat render IN [cameras] -o OUT.png [--depth D.png] [--alpha A.png] [--backend cpu|cuda]`:
// renders Gaussians (any format read_gaussian_input reads) with the splat renderer (render.h) and
// writes 8-bit PNGs (io/image.h): the colour image, and optionally the turbo-coloured expected
// depth and the accumulated opacity. Cameras come from camera_options.h; without any, one view
// frames the scene. Several views need an output name with a printf-style %d (view_%03d.png) or
// a directory (views/, written as views/view_000.png, ...); --depth and --alpha then need a %d too.
#include "commands.h"
#include "progress.h"
#include "input_checks.h"
#include "input_formats.h"

#include "camera_options.h"
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

#include <sys/stat.h>

#include <cctype>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

namespace avsplat::cli {

namespace {

struct RenderArgs {
    std::string input;
    CameraArgs cameras;
    std::size_t camera_index = 0;
    CLI::Option* camera_index_opt = nullptr;
    std::string output;
    std::string depth;
    std::string alpha;
    std::vector<float> background{0.0f, 0.0f, 0.0f};
    RenderOptions options;
};

bool is_directory_name(const std::string& path) {
    struct stat st;
    return !path.empty() && (path.back() == '/' || (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode)));
}

bool is_pattern(const std::string& path) { return path.find('%') != std::string::npos; }

void require_png(const std::string& path, const char* option) {
    if (!path.empty() && !is_directory_name(path) && file_extension(path) != ".png")
        throw IOError(path + ": " + option + " writes a PNG image (the name must end in .png)");
}

// The file of view `index` for an output name: a directory gets view_NNN.png, a pattern is
// formatted with the index, a plain name is used as it is.
std::string view_path(const std::string& out, std::size_t index, const char* option) {
    if (out.empty()) return out;
    if (is_directory_name(out)) {
        char name[32];
        std::snprintf(name, sizeof name, "view_%03zu.png", index);
        return out + (out.back() == '/' ? "" : "/") + name;
    }
    if (!is_pattern(out)) return out;
    // One integer conversion (%d, %03d, ...), nothing else, so that the name cannot misformat.
    const auto p = out.find('%');
    std::size_t q = p + 1;
    while (q < out.size() && std::isdigit(static_cast<unsigned char>(out[q]))) ++q;
    if (q >= out.size() || out[q] != 'd' || out.find('%', q) != std::string::npos)
        throw CLI::ValidationError(option, "'" + out + "': the name may hold one %d (or %0Nd) and no other %");
    char buf[4096];
    std::snprintf(buf, sizeof buf, out.c_str(), int(index));
    return buf;
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
    std::vector<Camera> file_cameras;
    if (!a.cameras.file.empty()) file_cameras = read_camera_file(a.cameras.file);
    const GaussianCloud cloud = read_gaussian_input(a.input);
    std::vector<Camera> cameras = a.cameras.file.empty() ? resolve_cameras(a.cameras, cloud) : file_cameras;
    const bool many_outputs = is_directory_name(a.output) || is_pattern(a.output);
    if (*a.camera_index_opt || (!many_outputs && !a.cameras.file.empty())) {
        // One view of a camera file: --camera-index, or the first camera for a plain output name.
        if (a.camera_index >= cameras.size())
            throw IOError(a.cameras.file + ": no camera at index " + std::to_string(a.camera_index) + " (the file holds " +
                          std::to_string(cameras.size()) + ")");
        cameras = {cameras[a.camera_index]};
    }
    if (cameras.size() > 1 && !many_outputs)
        throw CLI::ValidationError("--output", std::to_string(cameras.size()) +
                                                   " views need a name with %d (view_%03d.png) or a directory (views/)");
    for (const auto* extra : {&a.depth, &a.alpha})
        if (cameras.size() > 1 && !extra->empty() && !is_pattern(*extra) && !is_directory_name(*extra))
            throw CLI::ValidationError(extra == &a.depth ? "--depth" : "--alpha",
                                       "with several views the name needs a %d or a directory");
    if (is_directory_name(a.output) && a.output.back() == '/') {
        struct stat st;
        if (::stat(a.output.c_str(), &st) != 0) throw OutputError(a.output + ": no such directory");
    }
    Progress progress("rendering views", cameras.size());  // a bar on a terminal only
    for (std::size_t i = 0; i < cameras.size(); ++i) {
        const RenderResult r = render(cloud, cameras[i], options);
        progress.print("rendered " + std::to_string(cloud.size()) + " Gaussians at " + std::to_string(r.width) + "x" +
                       std::to_string(r.height) + " (" + to_string(options.backend) + ", " +
                       to_string(options.precision) + "): " + r.stats.summary());
        const std::string color = view_path(a.output, i, "--output");
        write_color_png(color, r.color.data(), r.width, r.height);
        progress.print("wrote " + color);
        if (!a.depth.empty()) {
            const std::string depth = view_path(a.depth, i, "--depth");
            write_depth_png(depth, r.depth.data(), r.width, r.height);
            progress.print("wrote " + depth);
        }
        if (!a.alpha.empty()) {
            const std::string alpha = view_path(a.alpha, i, "--alpha");
            write_alpha_png(alpha, r.alpha.data(), r.width, r.height);
            progress.print("wrote " + alpha);
        }
        progress.advance(1);
    }
    progress.finish();
#endif
}

}  // namespace

void add_render(CLI::App& app) {
    auto* cmd = app.add_subcommand("render", "Render Gaussians to PNG images from cameras, an orbit, or a default view of the scene");
    auto a = std::make_shared<RenderArgs>();
    cmd->add_option("input", a->input, "Gaussians: " + readable_formats(true))->required()->check(existing_input());
    add_camera_options(*cmd, a->cameras, "--camera,--cameras",
                       "Cameras (none given: one view framing the scene's 2nd-98th percentile bounds, up = -y)");
    a->camera_index_opt = cmd->add_option("--camera-index", a->camera_index,
                                          "render only this camera of the file (default: the first for a plain -o "
                                          "name, all for a %d name or a directory)");
    a->camera_index_opt->needs(a->cameras.file_opt);
    cmd->add_option("-o,--output", a->output,
                    "colour image (.png); for several views a name with %d (view_%03d.png) or a directory "
                    "(views/ -> views/view_000.png, ...)")
        ->required();
    cmd->add_option("--depth", a->depth, "also write the expected depth, turbo-coloured (.png, %d or directory)");
    cmd->add_option("--alpha", a->alpha, "also write the accumulated opacity, grayscale (.png, %d or directory)");
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
