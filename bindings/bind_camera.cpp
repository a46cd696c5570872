#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "paths.h"

#include "avsplat/core/camera.h"
#include "avsplat/core/framing.h"
#include "avsplat/io/colmap.h"
#include "avsplat/io/camera_json.h"

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <sstream>

namespace avsplat::python {

namespace py = pybind11;

void bind_camera(py::module_& m) {
    py::class_<Camera>(m, "Camera", R"doc(
Pinhole camera with OpenCV axes (x right, y down, z forward).

``Camera(fx, fy, cx, cy, width, height, world_to_camera=identity, near=0.01, far=1e10)``.
Pixel (i, j) has its centre at (i + 0.5, j + 0.5).

Parameters
----------
fx, fy, cx, cy : float
    Focal lengths and principal point, in pixels.
width, height : int
    Image size in pixels.
world_to_camera : array_like, shape (4, 4), optional
    A rigid transform; the identity by default.
near, far : float
    Clipping depths, 0 < near < far.)doc")
        .def(py::init([](double fx, double fy, double cx, double cy, int width, int height,
                         const OptionalArrayLike& w2c, double near, double far) {
                 Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
                 if (!w2c.is_none()) {
                     const auto a = as_array<double>(w2c, "world_to_camera", {4, 4}, "4, 4", "float");
                     if (a.ndim() != 2 || a.shape(0) != 4 || a.shape(1) != 4)
                         throw py::value_error("world_to_camera: expected shape (4, 4)");
                     for (int r = 0; r < 4; ++r)
                         for (int c = 0; c < 4; ++c) M(r, c) = a.at(r, c);
                 }
                 Camera cam(fx, fy, cx, cy, width, height, M, near, far);
                 cam.validate();
                 return cam;
             }),
             py::arg("fx"), py::arg("fy"), py::arg("cx"), py::arg("cy"), py::arg("width"),
             py::arg("height"), py::arg("world_to_camera") = py::none(), py::arg("near") = 0.01,
             py::arg("far") = 1e10)
        .def_static("look_at", &Camera::look_at, py::arg("eye"), py::arg("target"), py::arg("up"),
                    py::arg("fov_y_degrees"), py::arg("width"), py::arg("height"),
                    py::arg("near") = 0.01, py::arg("far") = 1e10,
                    R"doc(
A camera at `eye` looking at `target`, with `up` pointing up in the image.

The camera's z axis is the view direction (target - eye), its x axis is view x up (right in the
image) and its y axis is view x x, which points down in the image: `up` is the world direction
that appears up (towards row 0), projected off the view direction. It is not assumed to be +y:
avsplat's world has OpenCV/3DGS axes (y down), so for 3DGS and COLMAP scenes pass
up=(0, -1, 0), as avsplat.default_camera does.

Parameters
----------
eye, target : (3,) array_like of float
    Camera centre and the point it looks at, world units; eye != target.
up : (3,) array_like of float
    World direction shown up in the image; not parallel to target - eye.
fov_y_degrees : float
    Vertical field of view in (0, 180); fx = fy = (height / 2) / tan(fov_y / 2), principal
    point at the image centre.
width, height : int
    Image size in pixels (>= 1).
near, far : float
    Clipping depths, 0 < near < far.

Returns
-------
Camera

Raises
------
ValueError
    Naming the bad argument (eye == target, up parallel to the view, fov or size out of range).)doc")
        .def_readwrite("fx", &Camera::fx, "focal length in pixels along x (float)")
        .def_readwrite("fy", &Camera::fy, "focal length in pixels along y (float)")
        .def_readwrite("cx", &Camera::cx, "principal point x in pixels (float)")
        .def_readwrite("cy", &Camera::cy, "principal point y in pixels (float)")
        .def_readwrite("width", &Camera::width, "image width in pixels (int)")
        .def_readwrite("height", &Camera::height, "image height in pixels (int)")
        .def_readwrite("world_to_camera", &Camera::world_to_camera, "(4, 4) float64 rigid transform")
        .def_readwrite("near", &Camera::near, "near clipping depth (camera-space z)")
        .def_readwrite("far", &Camera::far, "far clipping depth (camera-space z)")
        .def_readwrite("name", &Camera::name, "free-form name (str), kept by the JSON files")
        .def_property_readonly("position", &Camera::position, "(3,) float64 camera centre in world coordinates")
        .def("camera_to_world", &Camera::camera_to_world,
             "(4, 4) float64 inverse of world_to_camera (its last column is the position).")
        .def("validate", &Camera::validate, "Raises ValueError naming the bad field.")
        .def("__repr__", [](const Camera& c) {
            std::ostringstream os;
            const Eigen::Vector3d p = c.position() + Eigen::Vector3d::Zero();  // no "-0" in the repr
            os << "Camera(" << c.width << "x" << c.height << ", fx=" << c.fx << ", fy=" << c.fy
               << ", cx=" << c.cx << ", cy=" << c.cy << ", position=(" << p.x() << ", " << p.y()
               << ", " << p.z() << ")" << (c.name.empty() ? "" : ", name='" + c.name + "'") << ")";
            return os.str();
        });

    m.def(
        "read_cameras_json", [](const PathLike& path) { return read_cameras_json(fs_path(path)); },
        py::arg("path"),
        "All cameras of a JSON file (str or os.PathLike): avsplat's format, 3DGS cameras.json or "
        "nerfstudio transforms.json. Raises OSError naming the file and the bad field.");
    m.def(
        "read_camera_json",
        [](const PathLike& path, std::size_t index) { return read_camera_json(fs_path(path), index); },
        py::arg("path"), py::arg("index") = 0,
        "The camera at `index` (int >= 0) of a cameras JSON file (str or os.PathLike), in any\n"
        "format read_cameras_json reads. Raises OSError naming the file when it cannot be read,\n"
        "is malformed or has no camera at `index`.");
    m.def(
        "write_cameras_json",
        [](const PathLike& path, const std::vector<Camera>& cams) { write_cameras_json(fs_path(path), cams); },
        py::arg("path"), py::arg("cameras"),
        "Writes `cameras` (a list of Camera) to `path` (str or os.PathLike) in avsplat's JSON\n"
        "format; read_cameras_json reads it back exactly. Raises OSError naming the file when it\n"
        "cannot be written.");
    m.def(
        "write_camera_json",
        [](const PathLike& path, const Camera& cam) { write_camera_json(fs_path(path), cam); },
        py::arg("path"), py::arg("camera"),
        "Writes one Camera to `path` (str or os.PathLike) as a one-element list in avsplat's JSON\n"
        "format. Raises OSError naming the file when it cannot be written.");

    m.def(
        "robust_bounds",
        [](const GaussianCloud& cloud, double low, double high) {
            const auto [lo, hi] = robust_bounds(cloud, low, high);
            return py::make_tuple(lo, hi);
        },
        py::arg("cloud"), py::arg("low_percentile") = 2.0, py::arg("high_percentile") = 98.0, R"doc(
Per-axis percentiles of the means: a box that ignores a few far floaters.

Parameters
----------
cloud : GaussianCloud
    Non-finite means are skipped.
low_percentile, high_percentile : float
    In [0, 100], low <= high; interpolated linearly as numpy.percentile does.

Returns
-------
(lo, hi) : tuple of (3,) float64 ndarray
    The low and high corners.

Raises
------
ValueError
    When the cloud has no finite mean or the percentiles are out of range.)doc");
    auto framing = [](const Eigen::Vector3d& up, double fov, int width, int height, double elevation,
                      double azimuth, const std::optional<double>& radius,
                      const std::optional<Eigen::Vector3d>& target, double low, double high) {
        FramingOptions o;
        o.up = up;
        o.fov_y_degrees = fov;
        o.width = width;
        o.height = height;
        o.elevation_degrees = elevation;
        o.azimuth_degrees = azimuth;
        o.radius = radius;
        o.target = target;
        o.low_percentile = low;
        o.high_percentile = high;
        return o;
    };
    const FramingOptions d;
    static const char* framing_params = R"doc(
up : (3,) array_like of float
    World direction shown up in the images. Default (0, -1, 0): avsplat's world has OpenCV/3DGS
    axes (y down), which every reader converts to, and 3DGS/COLMAP scenes are y-down.
fov_y_degrees : float
    Vertical field of view in (0, 180).
width, height : int
    Image size in pixels.
elevation_degrees : float
    Angle of the camera above the target, in (-90, 90).
azimuth_degrees : float
    Of the first camera, about `up`; 0 looks along +z.
radius : float or None
    Distance from the target; None: the bounds' bounding sphere just fits the field of view.
target : (3,) array_like of float or None
    Point looked at; None: the centre of avsplat.robust_bounds.
low_percentile, high_percentile : float
    The robust bounds (see avsplat.robust_bounds).)doc";
    m.def(
        "default_camera",
        [framing](const GaussianCloud& cloud, const Eigen::Vector3d& up, double fov, int width, int height,
                  double elevation, double azimuth, const std::optional<double>& radius,
                  const std::optional<Eigen::Vector3d>& target, double low, double high) {
            return default_camera(cloud, framing(up, fov, width, height, elevation, azimuth, radius, target, low, high));
        },
        py::arg("cloud"), py::arg("up") = d.up, py::arg("fov_y_degrees") = d.fov_y_degrees, py::arg("width") = d.width,
        py::arg("height") = d.height, py::arg("elevation_degrees") = d.elevation_degrees,
        py::arg("azimuth_degrees") = d.azimuth_degrees, py::arg("radius") = py::none(), py::arg("target") = py::none(),
        py::arg("low_percentile") = d.low_percentile, py::arg("high_percentile") = d.high_percentile,
        (std::string(R"doc(
A camera that frames the scene: its robust bounds (2nd-98th percentiles of the means) all
project inside the image, seen from `elevation_degrees` above, with `up` up.

Parameters
----------
cloud : GaussianCloud)doc") + framing_params + R"doc(

Returns
-------
Camera
    Named "default".

Raises
------
ValueError
    Naming the option out of range, or when the cloud has no finite mean.)doc").c_str());
    m.def(
        "orbit_cameras",
        [framing](const GaussianCloud& cloud, int n, const Eigen::Vector3d& up, double fov, int width, int height,
                  double elevation, double azimuth, const std::optional<double>& radius,
                  const std::optional<Eigen::Vector3d>& target, double low, double high) {
            return orbit_cameras(cloud, n,
                                 framing(up, fov, width, height, elevation, azimuth, radius, target, low, high));
        },
        py::arg("cloud"), py::arg("n"), py::arg("up") = d.up, py::arg("fov_y_degrees") = d.fov_y_degrees,
        py::arg("width") = d.width, py::arg("height") = d.height, py::arg("elevation_degrees") = d.elevation_degrees,
        py::arg("azimuth_degrees") = d.azimuth_degrees, py::arg("radius") = py::none(), py::arg("target") = py::none(),
        py::arg("low_percentile") = d.low_percentile, py::arg("high_percentile") = d.high_percentile,
        (std::string(R"doc(
`n` cameras evenly spaced in azimuth around the scene (360 / n degrees apart, counter-clockwise
seen from above), at the distance and elevation of avsplat.default_camera; the first one is
the default camera.

Parameters
----------
cloud : GaussianCloud
n : int
    Number of views (>= 1).)doc") + framing_params + R"doc(

Returns
-------
list of Camera
    Named "orbit_000", "orbit_001", ...

Raises
------
ValueError
    When n < 1, naming the option out of range, or when the cloud has no finite mean.)doc").c_str());
    m.def(
        "read_colmap_cameras", [](const PathLike& path) { return read_colmap_cameras(fs_path(path)); },
        py::arg("path"), R"doc(
The cameras of a COLMAP sparse model, one per registered image, in images file order.

Parameters
----------
path : str or os.PathLike
    A model directory holding cameras.bin and images.bin (preferred) or cameras.txt and
    images.txt, or one of those files.

Returns
-------
list of Camera
    Named after the images; pose from COLMAP's world-to-camera quaternion (qw, qx, qy, qz) and
    translation, whose axes are avsplat's (OpenCV). PINHOLE and SIMPLE_PINHOLE intrinsics.

Raises
------
OSError
    Naming the file and line or record: a missing or malformed file, an unknown camera id, or
    a camera model with distortion (named with its camera id; undistort the images first).)doc");
}

}  // namespace avsplat::python
