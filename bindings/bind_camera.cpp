#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "paths.h"

#include "avsplat/core/camera.h"
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

Parameters
----------
eye, target, up : array_like, shape (3,)
    World points and the up direction (float64); eye != target, up not parallel to
    target - eye.
fov_y_degrees : float
    Vertical field of view in (0, 180); fx = fy = (height / 2) / tan(fov_y / 2), the principal
    point at the image centre.
width, height : int
    Image size in pixels, >= 1.
near, far : float
    Clipping depths, 0 < near < far.

Returns
-------
Camera

Raises
------
ValueError
    Naming the bad argument.)doc")
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
}

}  // namespace avsplat::python
