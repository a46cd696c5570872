// The camera options of the web viewer's commands (view, and convert to .html): the camera
// options of render (camera_options.h) but one view: the first camera of a --cameras file, an
// explicit --eye/--target/--up/--fov/--size, or the default framing. --orbit is refused.
#pragma once

#include "camera_options.h"

#include "avsplat/view/web_viewer.h"

#include <utility>

namespace avsplat::cli {

/// Adds the camera options (add_camera_options) in the help group `group`.
void add_viewer_camera_options(CLI::App& cmd, CameraArgs& a, const std::string& group);

/// The page's initial camera and its orbit settings (up, and the target when given).
std::pair<Camera, WebViewerOptions> resolve_viewer_camera(const CameraArgs& a, const GaussianCloud& cloud);

}  // namespace avsplat::cli
