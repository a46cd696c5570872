#include "module.h"
#include "paths.h"
#include "release_gil.h"

#include "avsplat/core/framing.h"
#include "avsplat/view/web_viewer.h"

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

namespace avsplat::python {

namespace py = pybind11;

namespace {

WebViewerOptions viewer_options(const std::array<float, 3>& background, const Eigen::Vector3d& up,
                                const std::optional<Eigen::Vector3d>& target, const std::string& title) {
    WebViewerOptions o;
    o.background = background;
    o.up = up;
    o.target = target;
    o.title = title;
    return o;
}

Camera camera_or_default(const GaussianCloud& cloud, const std::optional<Camera>& camera) {
    return camera ? *camera : default_camera(cloud);
}

const char* const kOptionsDoc = R"doc(
camera : Camera, optional
    The initial view; default: ``default_camera(cloud)`` (the scene's robust bounds, seen from
    up = -y). The page scales it to its own size, keeping the vertical field of view.
viewer_dir : str, optional
    The installed viewer's folder; default: ``find_web_viewer()``.
background : (float, float, float)
    RGB behind the splats, each in [0, 1].
up : (float, float, float)
    World direction kept up while orbiting.
target : (float, float, float), optional
    The point the viewer orbits around; default: the point of the camera's axis nearest to the
    centre of the scene's robust bounds.
title : str
    The page's title.)doc";

}  // namespace

void bind_view(py::module_& m) {
    m.def("web_viewer_search_path", &web_viewer_search_path, R"doc(
The folders where the installed web viewer is looked for, in order: ``$AVSPLAT_WEB_VIEWER`` when
set (then only it), ``share/avsplat/web-viewer`` beside the running program's folder, the source
tree's ``build-node/viewer/dist``, then the configured install prefix's ``share/avsplat/web-viewer``. ``bash scripts/web_viewer.sh`` installs it (needs npm).)doc");
    m.def("find_web_viewer", &find_web_viewer, R"doc(
The first folder of ``web_viewer_search_path()`` that holds the viewer (``viewer.html`` and
``avsplat-viewer.js``).

Raises
------
FileError
    Naming the folders looked in and how to install the viewer, when none holds it.)doc");
    m.def(
        "web_viewer_page",
        [](const GaussianCloud& cloud, const std::optional<Camera>& camera, const std::optional<std::string>& viewer_dir,
           const std::array<float, 3>& background, const Eigen::Vector3d& up,
           const std::optional<Eigen::Vector3d>& target, const std::string& title) {
            const std::string dir = viewer_dir ? *viewer_dir : find_web_viewer();
            std::string page;
            {
                py::gil_scoped_release release;
                page = web_viewer_page(cloud, camera_or_default(cloud, camera), dir,
                                       viewer_options(background, up, target, title));
            }
            return page;
        },
        py::arg("cloud"), py::arg("camera") = py::none(), py::kw_only(), py::arg("viewer_dir") = py::none(),
        py::arg("background") = std::array<float, 3>{0.0f, 0.0f, 0.0f},
        py::arg("up") = Eigen::Vector3d(0.0, -1.0, 0.0), py::arg("target") = py::none(),
        py::arg("title") = "avsplat viewer",
        (std::string(R"doc(
One self-contained HTML page that shows ``cloud`` in a browser (Spark on three.js, embedded), the
scene embedded as a float32 3DGS PLY: it opens offline. The first frame follows the CPU
renderer's 3DGS conventions from ``camera``; dragging orbits, the wheel zooms.

Parameters
----------
cloud : GaussianCloud)doc") + kOptionsDoc + R"doc(

Returns
-------
str
    The page (the viewer's bundle, about 3 MB, plus 4/3 of the PLY's bytes).

Raises
------
FileError
    When the viewer is not installed (the message says how to install it).
ValueError
    For an invalid camera or option, naming it.)doc").c_str());
    m.def(
        "write_html",
        [](const py::object& path, const GaussianCloud& cloud, const std::optional<Camera>& camera,
           const std::optional<std::string>& viewer_dir, const std::array<float, 3>& background,
           const Eigen::Vector3d& up, const std::optional<Eigen::Vector3d>& target, const std::string& title) {
            const std::string p = fs_path(path);
            const std::string dir = viewer_dir ? *viewer_dir : find_web_viewer();
            py::gil_scoped_release release;
            write_html(p, cloud, camera_or_default(cloud, camera), dir, viewer_options(background, up, target, title));
        },
        py::arg("path"), py::arg("cloud"), py::arg("camera") = py::none(), py::kw_only(),
        py::arg("viewer_dir") = py::none(), py::arg("background") = std::array<float, 3>{0.0f, 0.0f, 0.0f},
        py::arg("up") = Eigen::Vector3d(0.0, -1.0, 0.0), py::arg("target") = py::none(),
        py::arg("title") = "avsplat viewer",
        (std::string(R"doc(
Write ``web_viewer_page(cloud, camera, ...)`` to ``path`` (atomically): one ``.html`` file that
shows the scene in any browser, offline (what ``avsplat convert SCENE out.html`` writes).

Parameters
----------
path : str or os.PathLike
cloud : GaussianCloud)doc") + kOptionsDoc + R"doc(

Raises
------
FileError
    When the viewer is not installed, or naming ``path`` when it cannot be written.
ValueError
    For an invalid camera or option, naming it.)doc").c_str());
}

}  // namespace avsplat::python
