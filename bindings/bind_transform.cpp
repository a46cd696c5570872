// Python bindings of avsplat/core/transform.h: transform, sh_rotation, coordinate_system_change.
#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "release_gil.h"

#include "avsplat/core/transform.h"

#include <Eigen/Geometry>

#include <cmath>
#include <string>

namespace avsplat::python {

namespace py = pybind11;

namespace {

// A 3x3 matrix, or a quaternion (w, x, y, z) of any non-zero length, as a rotation matrix.
Eigen::Matrix3d rotation_arg(const py::object& obj) {
    if (obj.is_none()) return Eigen::Matrix3d::Identity();
    const py::array probe = py::module_::import("numpy").attr("asarray")(obj);
    if (probe.ndim() == 1 && probe.shape(0) == 4) {
        const auto q = as_array<double>(obj, "rotation", {4}, "4", "float");
        const double* v = q.data();
        const double norm = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3]);
        if (!(std::isfinite(norm) && norm > 0))
            throw py::value_error("rotation: a quaternion (w, x, y, z) must be finite and non-zero");
        return Eigen::Quaterniond(v[0] / norm, v[1] / norm, v[2] / norm, v[3] / norm).toRotationMatrix();
    }
    const auto m = as_array<double>(obj, "rotation", {3, 3}, "3, 3", "float");
    Eigen::Matrix3d r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = m.data()[3 * i + j];
    return r;
}

py::array_t<double> matrix_out(const Eigen::MatrixXd& m) {
    py::array_t<double> a({static_cast<py::ssize_t>(m.rows()), static_cast<py::ssize_t>(m.cols())});
    for (Eigen::Index i = 0; i < m.rows(); ++i)
        for (Eigen::Index j = 0; j < m.cols(); ++j) a.mutable_at(i, j) = m(i, j);
    return a;
}

}  // namespace

void bind_transform(py::module_& m) {
    m.def(
        "transform",
        [](const GaussianCloud& cloud, const OptionalArrayLike& rotation, const OptionalArrayLike& translation,
           double scale) {
            const Eigen::Matrix3d r = rotation_arg(rotation);
            Eigen::Vector3d t = Eigen::Vector3d::Zero();
            if (!translation.is_none()) {
                const auto a = as_array<double>(translation, "translation", {3}, "3", "float");
                t = Eigen::Vector3d(a.data()[0], a.data()[1], a.data()[2]);
            }
            ReleaseGil release(cloud);
            return transform(cloud, r, t, scale);
        },
        py::arg("cloud"), py::arg("rotation") = py::none(), py::arg("translation") = py::none(),
        py::arg("scale") = 1.0, R"doc(
Move a cloud by x -> scale * R x + translation, colours included.

Means become scale * R mu + t, scales scale * s, quaternions q_R * q, and SH bands 1..3 are
rotated exactly (``sh_rotation``), so rendering the result from the camera moved the same way
gives the original image. Opacity, confidence and extras are copied.

Parameters
----------
cloud : GaussianCloud
    N Gaussians; validated first.
rotation : array_like, shape (3, 3) or (4,), optional
    An orthogonal matrix (det -1 allowed: a change of handedness), or a quaternion w, x, y, z
    (normalised here); None: the identity.
translation : array_like, shape (3,), optional
    None: zero.
scale : float
    > 0.

Returns
-------
GaussianCloud
    A new cloud.

Raises
------
ValueError
    For a matrix that is not orthogonal (within 1e-5), a non-finite translation, scale <= 0, or
    an invalid cloud.)doc");
    m.def(
        "sh_rotation",
        [](int band, const ArrayLike& rotation) { return matrix_out(sh_rotation(band, rotation_arg(rotation))); },
        py::arg("band"), py::arg("rotation"), R"doc(
The matrix that rotates the SH coefficients of one band.

D satisfies sum (D a)_m Y_m(d) = sum a_m Y_m(R^T d) for every direction d (the renderer's
basis and order); exact to rounding.

Parameters
----------
band : int
    l, 0..3.
rotation : array_like, shape (3, 3) or (4,)
    An orthogonal matrix R, or a quaternion w, x, y, z.

Returns
-------
ndarray, shape (2l+1, 2l+1), float64
    D.

Raises
------
ValueError
    For a band outside 0..3 or a matrix that is not orthogonal.)doc");
    m.def(
        "coordinate_system_change",
        [](const std::string& from, const std::string& to) { return matrix_out(coordinate_system_change(from, to)); },
        py::arg("from_axes"), py::arg("to_axes"), R"doc(
The matrix that re-expresses coordinates given in one axis convention in another.

A convention is three letters saying where +x, +y, +z point, one of R/L, U/D, F/B each: 'RDF'
(OpenCV, avsplat's cameras), 'RUB' (OpenGL, SPZ), ... Pass the result to ``transform`` as the
rotation.

Parameters
----------
from_axes, to_axes : str
    The conventions, e.g. "RUB" and "RDF".

Returns
-------
ndarray, shape (3, 3), float64
    The rotation (or reflection) matrix.

Raises
------
ValueError
    Naming a malformed convention.)doc");
}

}  // namespace avsplat::python
