// `avsplat cameras orbit IN -o CAMS.json [--orbit N ...]` and `avsplat cameras colmap MODEL -o
// CAMS.json`: writes a camera file in avsplat's JSON (io/camera_json.h) that render, prune and
// simplify read with --cameras: the orbit (or default view) of a scene, or the pinhole cameras of
// a COLMAP model (io/colmap.h).
#include "camera_options.h"
#include "commands.h"
#include "input_formats.h"

#include "avsplat/io/camera_json.h"
#include "avsplat/io/colmap.h"
#include "avsplat/predictions/prediction_npz.h"

#include <cstdio>
#include <memory>
#include <string>

namespace avsplat::cli {

namespace {

struct CamerasArgs {
    std::string input, output;
    CameraArgs cameras;
};

void write_and_report(const std::string& path, const std::vector<Camera>& cams) {
    write_cameras_json(path, cams);
    std::printf("wrote %zu camera%s to %s\n", cams.size(), cams.size() == 1 ? "" : "s", path.c_str());
}

}  // namespace

void add_cameras(CLI::App& app) {
    auto* cmd = app.add_subcommand("cameras", "Write a camera file (avsplat JSON): an orbit of a scene, or a COLMAP model's cameras");
    cmd->require_subcommand(1);
    {
        auto* orbit = cmd->add_subcommand(
            "orbit", "Cameras around a scene: --orbit N views (default 1: the default framing) or one --eye view");
        auto a = std::make_shared<CamerasArgs>();
        orbit->add_option("input", a->input, "Gaussians: " + readable_formats(true))->required()->check(CLI::ExistingPath);
        orbit->add_option("-o,--output", a->output, "cameras JSON to write")->required();
        add_camera_options(*orbit, a->cameras, "--cameras",
                           "Cameras (none given: one view framing the scene's 2nd-98th percentile bounds, up = -y)");
        orbit->callback([a] {
            if (!a->cameras.file.empty())
                throw CLI::ValidationError("--cameras", "use `avsplat cameras colmap` to convert a camera file");
            write_and_report(a->output, resolve_cameras(a->cameras, read_gaussian_input(a->input)));
        });
    }
    {
        auto* colmap = cmd->add_subcommand(
            "colmap", "The pinhole cameras of a COLMAP model (cameras/images .bin or .txt), one per registered image");
        auto a = std::make_shared<CamerasArgs>();
        colmap->add_option("model", a->input, "a COLMAP sparse model directory, or its cameras/images file")
            ->required()
            ->check(CLI::ExistingPath);
        colmap->add_option("-o,--output", a->output, "cameras JSON to write")->required();
        colmap->callback([a] { write_and_report(a->output, read_colmap_cameras(a->input)); });
    }
}

}  // namespace avsplat::cli
