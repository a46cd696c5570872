// The web viewer: HTML pages that show a Gaussian cloud in a browser with Spark (a Gaussian-splat
// renderer on three.js), the same page for `avsplat view` (scene fetched from a URL),
// self-contained `.html` files (scene embedded) and avsplat.show() in notebooks.
//
// The viewer is not part of the library: scripts/web_viewer.sh installs it from npm (Spark and
// three.js, pinned) and bundles it into a folder holding `viewer.html` (the page template) and
// `avsplat-viewer.js` (one JavaScript module). The pages embed that bundle, so they need no
// network. A page's first frame is drawn from the given camera with the CPU renderer's 3DGS
// conventions (RenderOptions' defaults: low-pass 0.3, 3-sigma footprint, alpha threshold 1/255,
// view-depth order); dragging then orbits around WebViewerOptions::target.
//
// The scene travels as a binary 3DGS PLY written by write_ply (float32, so nothing is lost on
// the way; 4 * (14 + 3 * coefficients) bytes per Gaussian, a third more when embedded as base64).
#pragma once
#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include <Eigen/Core>
#include <array>
#include <optional>
#include <string>
#include <vector>

namespace avsplat {

struct WebViewerOptions {
    /// RGB behind the splats, each in [0, 1].
    std::array<float, 3> background{0.0f, 0.0f, 0.0f};
    /// World direction kept up while orbiting (avsplat's worlds are y-down: -y).
    Eigen::Vector3d up{0.0, -1.0, 0.0};
    /// The point the viewer orbits around; unset: the point of the camera's optical axis nearest
    /// to the centre of the scene's robust bounds (core/framing.h), or 1 unit ahead when that
    /// centre lies behind the camera.
    std::optional<Eigen::Vector3d> target;
    /// The page's title.
    std::string title = "avsplat viewer";
};

/// The folders where the installed viewer is looked for, in order: $AVSPLAT_WEB_VIEWER when set
/// (then only it), share/avsplat/web-viewer beside the running program's folder (<prefix>/bin ->
/// <prefix>/share), the source tree's build-node/viewer/dist, then the configured install
/// prefix's share/avsplat/web-viewer. Reads only /proc/self/exe.
std::vector<std::string> web_viewer_search_path();

/// The first folder of web_viewer_search_path() that holds viewer.html and avsplat-viewer.js.
/// Throws IOError naming the folders looked in and how to install the viewer when none does.
std::string find_web_viewer();

/// The scene as the viewer reads it: the bytes of a binary 3DGS PLY of `cloud` (write_ply's
/// layout). Throws what write_ply throws. Cost: one pass over the cloud; holds the bytes.
std::string web_viewer_scene(const GaussianCloud& cloud);

/// A page showing `cloud` from `camera`, the scene embedded (base64), the viewer from the folder
/// `viewer_dir` (find_web_viewer()). Throws std::invalid_argument for an invalid camera or
/// option (naming it), IOError when the viewer's files cannot be read. Size: the viewer's
/// bundle (about 3 MB) plus 4/3 of web_viewer_scene's bytes.
std::string web_viewer_page(const GaussianCloud& cloud, const Camera& camera, const std::string& viewer_dir,
                            const WebViewerOptions& options = {});

/// A page that fetches the scene (web_viewer_scene's bytes) from `scene_url`, for a server; the
/// camera, options and errors as web_viewer_page. The target, when unset, is computed from `cloud`.
std::string web_viewer_page_for_url(const GaussianCloud& cloud, const Camera& camera,
                                    const std::string& scene_url, const std::string& viewer_dir,
                                    const WebViewerOptions& options = {});

/// Writes web_viewer_page(...) to `path` (atomically: io/atomic_file.h). Throws as
/// web_viewer_page and IOError naming `path` when it cannot be written.
void write_html(const std::string& path, const GaussianCloud& cloud, const Camera& camera,
                const std::string& viewer_dir, const WebViewerOptions& options = {});

}  // namespace avsplat
