#include "camera_options.h"

#include "avsplat/core/framing.h"
#include "avsplat/io/camera_json.h"
#include "avsplat/io/colmap.h"

#include <cstdio>

namespace avsplat::cli {

namespace {

Eigen::Vector3d vec3(const std::vector<double>& v) { return {v[0], v[1], v[2]}; }

void parse_size(const std::string& s, int& w, int& h) {
    int n = 0;
    if (std::sscanf(s.c_str(), "%dx%d%n", &w, &h, &n) != 2 || n != int(s.size()) || w <= 0 || h <= 0)
        throw CLI::ValidationError("--size", "expected WIDTHxHEIGHT in pixels, e.g. 1024x768, got '" + s + "'");
}

}  // namespace

void add_camera_options(CLI::App& cmd, CameraArgs& a, const std::string& file_flags, const std::string& group) {
    a.file_opt = cmd.add_option(file_flags, a.file,
                                "camera file: avsplat JSON, 3DGS cameras.json, nerfstudio transforms.json, or a "
                                "COLMAP model (a directory with cameras/images .bin or .txt, or one of those files)")
                     ->check(CLI::ExistingPath)
                     ->group(group);
    a.orbit_opt = cmd.add_option("--orbit", a.orbit, "N views evenly spaced around the scene (about --up)")
                      ->check(CLI::PositiveNumber)
                      ->group(group);
    cmd.add_option("--elevation", a.elevation, "orbit/default view: degrees above the target, in (-90, 90)")
        ->capture_default_str()
        ->check(CLI::Range(-89.999, 89.999))
        ->group(group);
    a.radius_opt = cmd.add_option("--radius", a.radius,
                                  "orbit/default view: distance from the target (default: the bounds fill the view)")
                       ->check(CLI::PositiveNumber)
                       ->group(group);
    a.eye_opt = cmd.add_option("--eye", a.eye, "camera position X,Y,Z (looks at --target)")
                    ->delimiter(',')
                    ->expected(3)
                    ->group(group);
    a.target_opt = cmd.add_option("--target", a.target, "point looked at X,Y,Z (default: the centre of the bounds)")
                       ->delimiter(',')
                       ->expected(3)
                       ->group(group);
    cmd.add_option("--up", a.up, "world direction shown up X,Y,Z (default 0,-1,0: 3DGS/COLMAP scenes are y-down)")
        ->delimiter(',')
        ->expected(3)
        ->group(group);
    cmd.add_option("--fov", a.fov, "vertical field of view in degrees, in (0, 180)")
        ->capture_default_str()
        ->check(CLI::Range(0.001, 179.999))
        ->group(group);
    cmd.add_option("--size", a.size, "image size WIDTHxHEIGHT (default 1024x768)")->group(group);
    a.file_opt->excludes(a.orbit_opt)->excludes(a.eye_opt)->excludes(a.target_opt);
    a.orbit_opt->excludes(a.eye_opt);
}

bool has_cameras(const CameraArgs& a) { return !a.file.empty() || a.orbit > 0 || !a.eye.empty(); }

std::vector<Camera> read_camera_file(const std::string& path) {
    if (is_colmap_model(path)) return read_colmap_cameras(path);
    return read_cameras_json(path);
}

std::vector<Camera> resolve_cameras(const CameraArgs& a, const GaussianCloud& cloud) {
    if (!a.file.empty()) return read_camera_file(a.file);
    FramingOptions o;
    if (!a.up.empty()) o.up = vec3(a.up);
    o.fov_y_degrees = a.fov;
    if (!a.size.empty()) parse_size(a.size, o.width, o.height);
    o.elevation_degrees = a.elevation;
    if (*a.radius_opt) o.radius = a.radius;
    if (!a.target.empty()) o.target = vec3(a.target);
    try {
        if (!a.eye.empty()) {
            const Eigen::Vector3d eye = vec3(a.eye);
            Eigen::Vector3d target;
            if (o.target) {
                target = *o.target;
            } else {
                const auto [lo, hi] = robust_bounds(cloud, o.low_percentile, o.high_percentile);
                target = 0.5 * (lo + hi);
            }
            const double distance = (target - eye).norm();
            Camera c = Camera::look_at(eye, target, o.up, o.fov_y_degrees, o.width, o.height, 1e-3 * distance,
                                       1e10 * std::max(1.0, distance));
            c.name = "eye";
            return {c};
        }
        if (a.orbit > 0) return orbit_cameras(cloud, a.orbit, o);
        return {default_camera(cloud, o)};
    } catch (const std::invalid_argument& e) {
        throw CLI::ValidationError("cameras", e.what());
    }
}

}  // namespace avsplat::cli
