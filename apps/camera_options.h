// The camera options shared by render, prune and simplify: a camera file (--cameras: avsplat
// JSON, 3DGS cameras.json, transforms.json or a COLMAP model), an orbit (--orbit N), an explicit
// look-at (--eye/--target/--up/--fov/--size), or, with none of them, the default framing of
// core/framing.h (the robust bounds seen from up = -y).
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

namespace avsplat::cli {

struct CameraArgs {
    std::string file;
    int orbit = 0;
    double elevation = 20.0;
    double radius = 0.0;
    std::vector<double> eye, target, up;
    double fov = 50.0;
    std::string size;
    CLI::Option *file_opt = nullptr, *orbit_opt = nullptr, *eye_opt = nullptr, *target_opt = nullptr,
                *radius_opt = nullptr;
};

/// Adds --cameras (also spelled `file_flags`), --orbit, --elevation, --radius, --eye, --target,
/// --up, --fov and --size to `cmd`, in the help group `group`.
void add_camera_options(CLI::App& cmd, CameraArgs& a, const std::string& file_flags = "--cameras",
                        const std::string& group = "Cameras (none given: no camera-based step)");

/// True when any camera option was given.
bool has_cameras(const CameraArgs& a);

/// The cameras the options ask for, framed on `cloud` where they need it. Throws IOError for a
/// bad camera file, CLI::ValidationError for a bad value.
std::vector<Camera> resolve_cameras(const CameraArgs& a, const GaussianCloud& cloud);

/// Reads a camera file: a COLMAP model (a directory, or cameras/images .txt/.bin) or a cameras
/// JSON (io/camera_json.h).
std::vector<Camera> read_camera_file(const std::string& path);

}  // namespace avsplat::cli
