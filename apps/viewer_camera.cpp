#include "viewer_camera.h"

#include "avsplat/core/error.h"

namespace avsplat::cli {

void add_viewer_camera_options(CLI::App& cmd, CameraArgs& a, const std::string& group) {
    add_camera_options(cmd, a, "--cameras", group);
}

std::pair<Camera, WebViewerOptions> resolve_viewer_camera(const CameraArgs& a, const GaussianCloud& cloud) {
    if (a.orbit > 0) throw CLI::ValidationError("--orbit", "the viewer starts from one camera: give --eye/--target, or none");
    const std::vector<Camera> cameras = resolve_cameras(a, cloud);
    if (cameras.empty()) throw IOError(a.file + ": holds no camera");
    WebViewerOptions options;
    if (a.up.size() == 3) options.up = Eigen::Vector3d(a.up[0], a.up[1], a.up[2]);
    if (a.target.size() == 3) options.target = Eigen::Vector3d(a.target[0], a.target[1], a.target[2]);
    return {cameras.front(), options};
}

}  // namespace avsplat::cli
