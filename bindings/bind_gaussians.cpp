#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "paths.h"
#include "release_gil.h"

#include "avsplat/core/gaussians.h"

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <sstream>

namespace avsplat::python {

namespace {

GaussianCloud make_cloud(const ArrayLike& means, const ArrayLike& scales,
                         const ArrayLike& rotations, const ArrayLike& opacities,
                         const ArrayLike& sh, const OptionalArrayLike& confidence) {
    const FloatArray m = as_float_array(means, "means", {-1, 3}, "N, 3");
    const py::ssize_t n = m.shape(0);
    const FloatArray s = as_float_array(scales, "scales", {n, 3}, "N, 3");
    const FloatArray r = as_float_array(rotations, "rotations", {n, 4}, "N, 4");
    FloatArray o = as_contiguous<float>(opacities, "opacities", "float");
    if (o && o.ndim() == 2) o = as_float_array(opacities, "opacities", {n, 1}, "N,) or (N, 1");
    else o = as_float_array(opacities, "opacities", {n}, "N");
    FloatArray c = as_contiguous<float>(sh, "sh", "float");
    if (c && c.ndim() == 2) c = as_float_array(sh, "sh", {n, 3}, "N, K, 3) or (N, 3");
    else c = as_float_array(sh, "sh", {n, -1, 3}, "N, K, 3");
    const int k = c.ndim() == 2 ? 1 : static_cast<int>(c.shape(1));
    const int degree = sh_degree_for_coeffs(k);
    if (degree < 0)
        throw py::value_error("sh: K = " + std::to_string(k) +
                              " coefficients per channel is not (d+1)^2 for an SH degree d in 0..3");
    FloatArray conf;
    if (!confidence.is_none()) conf = as_float_array(confidence, "confidence", {n}, "N");
    return GaussianCloud::from_arrays(static_cast<std::size_t>(n), degree, m.data(), s.data(),
                                      r.data(), o.data(), c.data(),
                                      confidence.is_none() ? nullptr : conf.data());
}

// Assigning a property copies into the existing storage, so views handed out earlier stay
// valid; the shape must match the cloud's.
void assign(std::vector<float>& dst, const py::handle& src, const char* arg,
            std::vector<py::ssize_t> shape, const char* dims) {
    const FloatArray a = as_float_array(src, arg, shape, dims);
    std::copy(a.data(), a.data() + a.size(), dst.data());
}

}  // namespace

void bind_gaussians(py::module_& m) {
    py::class_<SanitizeReport>(m, "SanitizeReport",
                               "What sanitize() dropped, counted under the first failing reason.")
        .def_readonly("kept", &SanitizeReport::kept, "Gaussians kept (int)")
        .def_readonly("dropped", &SanitizeReport::dropped, "Gaussians dropped (int), the sum of the reasons")
        .def_readonly("non_finite", &SanitizeReport::non_finite, "dropped for a NaN or Inf in any field")
        .def_readonly("negative_scale", &SanitizeReport::negative_scale, "dropped for a scale < 0")
        .def_readonly("zero_rotation", &SanitizeReport::zero_rotation, "dropped for a zero quaternion")
        .def_readonly("opacity_range", &SanitizeReport::opacity_range, "dropped for an opacity outside [0, 1]")
        .def("summary", &SanitizeReport::summary, "One line, e.g. 'kept 998, dropped 2 (non_finite 1, negative_scale 1)'.")
        .def("__repr__", [](const SanitizeReport& r) { return "SanitizeReport(" + r.summary() + ")"; });

    py::class_<GaussianCloud>(m, "GaussianCloud", R"doc(
A set of 3D Gaussians stored as float32 structure-of-arrays.

``GaussianCloud(means, scales, rotations, opacities, sh, confidence=None)``. Inputs of any dtype
or layout are converted once to C-contiguous float32. Properties return numpy views of the
cloud's storage (writes go through); assigning a property copies into it and needs the same
shape.

Parameters
----------
means : array_like, shape (N, 3)
    World positions.
scales : array_like, shape (N, 3)
    Linear axis lengths (not log).
rotations : array_like, shape (N, 4)
    Quaternions (w, x, y, z); need not be unit, must not be zero.
opacities : array_like, shape (N,)
    In [0, 1] (not logits); (N, 1) is accepted.
sh : array_like, shape (N, K, 3)
    SH coefficients, K = (d+1)^2 for degree d in 0..3, degree 0 first; (N, 3) is accepted as
    degree 0.
confidence : array_like, shape (N,), optional
    Per-Gaussian confidence.)doc")
        .def(py::init(&make_cloud), py::arg("means"), py::arg("scales"), py::arg("rotations"),
             py::arg("opacities"), py::arg("sh"), py::arg("confidence") = py::none())
        .def_static("empty", [](std::size_t n, int d) { return GaussianCloud(n, d); },
                    py::arg("n"), py::arg("sh_degree") = 0,
                    "n Gaussians at the origin: unit scales, identity rotations, opacity 1, SH 0.")
        .def("__len__", &GaussianCloud::size)
        .def_property_readonly("sh_degree", [](const GaussianCloud& c) { return c.sh_degree; },
                               "SH degree d in 0..3 (int)")
        .def_property_readonly("sh_coeffs", &GaussianCloud::sh_coeffs, "K = (d+1)^2 SH coefficients per channel")
        .def_readwrite("antialiased", &GaussianCloud::antialiased,
                       "bool: trained for antialiased rasterisation; pass render(..., antialiased=cloud.antialiased). "
                       "Read from and written to SPZ's header flag.")
        .def_property(
            "means",
            [](py::object self) {
                auto& c = self.cast<GaussianCloud&>();
                return view(c.means.data(), {(py::ssize_t)c.size(), 3}, self);
            },
            [](GaussianCloud& c, const ArrayLike& v) { assign(c.means, v, "means", {(py::ssize_t)c.size(), 3}, "N, 3"); },
            "(N, 3) float32 view")
        .def_property(
            "scales",
            [](py::object self) {
                auto& c = self.cast<GaussianCloud&>();
                return view(c.scales.data(), {(py::ssize_t)c.size(), 3}, self);
            },
            [](GaussianCloud& c, const ArrayLike& v) { assign(c.scales, v, "scales", {(py::ssize_t)c.size(), 3}, "N, 3"); },
            "(N, 3) float32 view, linear scales")
        .def_property(
            "rotations",
            [](py::object self) {
                auto& c = self.cast<GaussianCloud&>();
                return view(c.rotations.data(), {(py::ssize_t)c.size(), 4}, self);
            },
            [](GaussianCloud& c, const ArrayLike& v) { assign(c.rotations, v, "rotations", {(py::ssize_t)c.size(), 4}, "N, 4"); },
            "(N, 4) float32 view, quaternions (w, x, y, z)")
        .def_property(
            "opacities",
            [](py::object self) {
                auto& c = self.cast<GaussianCloud&>();
                return view(c.opacities.data(), {(py::ssize_t)c.size()}, self);
            },
            [](GaussianCloud& c, const ArrayLike& v) { assign(c.opacities, v, "opacities", {(py::ssize_t)c.size()}, "N"); },
            "(N,) float32 view, in [0, 1]")
        .def_property(
            "sh",
            [](py::object self) {
                auto& c = self.cast<GaussianCloud&>();
                return view(c.sh.data(), {(py::ssize_t)c.size(), (py::ssize_t)c.sh_coeffs(), 3}, self);
            },
            [](GaussianCloud& c, const ArrayLike& v) {
                assign(c.sh, v, "sh", {(py::ssize_t)c.size(), (py::ssize_t)c.sh_coeffs(), 3}, "N, K, 3");
            },
            "(N, K, 3) float32 view of the SH coefficients")
        .def_property(
            "confidence",
            [](py::object self) -> py::object {
                auto& c = self.cast<GaussianCloud&>();
                if (!c.has_confidence()) return py::none();
                return view(c.confidence.data(), {(py::ssize_t)c.size()}, self);
            },
            [](GaussianCloud& c, const OptionalArrayLike& v) {
                // Present -> present copies in place; adding or dropping the channel changes the
                // layout a running call reads. Dropping keeps the memory (clear() does not free),
                // so a view of it stays valid.
                if (v.is_none()) {
                    if (c.has_confidence()) refuse_if_in_use(c, "confidence");
                    c.confidence.clear();
                    return;
                }
                const FloatArray a = as_float_array(v, "confidence", {(py::ssize_t)c.size()}, "N");
                if (!c.has_confidence()) refuse_if_in_use(c, "confidence");
                c.confidence.assign(a.data(), a.data() + a.size());
            },
            "(N,) float32 view, or None when absent")
        .def_property_readonly(
            "extras",
            [](py::object self) {
                auto& c = self.cast<GaussianCloud&>();
                py::dict d;
                for (auto& e : c.extras) d[file_name_str(e.name)] = view(e.values.data(), {(py::ssize_t)c.size()}, self);
                return d;
            },
            "dict name -> (N,) float32 view of the extra channels")
        .def(
            "set_extra",
            [](GaussianCloud& c, const std::string& name, const ArrayLike& v) {
                const FloatArray a = as_float_array(v, "values", {(py::ssize_t)c.size()}, "N");
                if (!c.find_extra(name)) refuse_if_in_use(c, "set_extra");
                c.set_extra(name, std::vector<float>(a.data(), a.data() + a.size()));
            },
            py::arg("name"), py::arg("values"),
            "Adds or replaces an extra channel of N values. Replacing copies into the channel's storage, so\n"
            "views of it stay valid; adding one while another thread's call reads the cloud raises RuntimeError.")
        .def("covariance", &GaussianCloud::covariance, py::arg("i"),
             "3 x 3 covariance R S S^T R^T of Gaussian i (float64).")
        .def("bounding_box", &GaussianCloud::bounding_box,
             "(min, max) of the means as two (3,) arrays; ValueError when empty.")
        .def("validate", [](const GaussianCloud& c) { validate(c); },
             "Raises ValueError naming the field and the first bad index.")
        .def("sanitize", [](GaussianCloud& c) { return sanitize(c); },
             "Drops invalid Gaussians in place; returns a SanitizeReport.")
        .def("select",
             [](const GaussianCloud& c, py::array_t<long long, py::array::c_style | py::array::forcecast> idx) {
                 if (idx.dtype().kind() == 'b')
                     throw py::value_error("select: use select_mask for boolean masks");
                 std::vector<std::size_t> v(idx.size());
                 for (py::ssize_t k = 0; k < idx.size(); ++k) {
                     const long long x = idx.data()[k];
                     if (x < 0) throw py::index_error("select: indices[" + std::to_string(k) + "] is negative");
                     v[k] = static_cast<std::size_t>(x);
                 }
                 return select(c, v);
             },
             py::arg("indices"), "The Gaussians at the given indices, in that order.")
        .def("select_mask",
             [](const GaussianCloud& c, py::array_t<bool, py::array::c_style | py::array::forcecast> mask) {
                 std::vector<std::uint8_t> v(mask.data(), mask.data() + mask.size());
                 return select_mask(c, v);
             },
             py::arg("mask"), "The Gaussians whose mask entry is True.")
        .def(
            "__getitem__",
            [](const GaussianCloud& c, const IndexKey& key) {
                // numpy's own indexing of arange(n) gives numpy's semantics: slices, negative
                // indices, boolean masks of length n, integer arrays, and IndexError out of bounds.
                const py::object rows = py::module_::import("numpy").attr("arange")(c.size())[key];
                const auto idx = py::array_t<long long, py::array::c_style | py::array::forcecast>::ensure(rows);
                if (!idx || idx.ndim() > 1)
                    throw py::index_error("GaussianCloud index: expected an int, a slice, a boolean mask or an "
                                          "integer array");
                std::vector<std::size_t> v(std::size_t(idx.size()));
                for (py::ssize_t k = 0; k < idx.size(); ++k) v[std::size_t(k)] = std::size_t(idx.data()[k]);
                return select(c, v);
            },
            py::arg("key"), R"doc(
A new cloud of the Gaussians ``key`` picks, with numpy's indexing rules.

Parameters
----------
key : int, slice, (N,) bool array or integer array
    ``cloud[3]`` (a cloud of one Gaussian), ``cloud[10:20]``, ``cloud[::2]``, ``cloud[-5:]``,
    ``cloud[mask]`` (a boolean mask of length N), ``cloud[[4, 0, 4]]`` (indices, in that order,
    negative ones counted from the end).

Returns
-------
GaussianCloud
    A copy; confidence and extra channels come along.

Raises
------
IndexError
    An index out of bounds, a mask of the wrong length, or a key of another kind.
)doc")
        .def("copy", [](const GaussianCloud& c) { return GaussianCloud(c); },
             "A deep copy: new storage for every array, confidence and extras included.")
        .def("__repr__", [](const GaussianCloud& c) {
            std::ostringstream os;
            os << "GaussianCloud(n=" << c.size() << ", sh_degree=" << c.sh_degree
               << ", confidence=" << (c.has_confidence() ? "yes" : "no");
            if (!c.extras.empty()) {
                os << ", extras=[";
                for (std::size_t k = 0; k < c.extras.size(); ++k) os << (k ? ", " : "") << c.extras[k].name;
                os << "]";
            }
            os << ")";
            return os.str();
        });

    m.def("concatenate", &concatenate, py::arg("clouds"),
          "All Gaussians of a list of clouds; lower SH degrees are zero-padded.",
          py::call_guard<ReleaseGil>());
    m.def("sh_degree_for_coeffs", &sh_degree_for_coeffs, py::arg("k"),
          "The SH degree d with (d+1)^2 == k coefficients per channel (k in 1, 4, 9, 16 -> 0..3);\n"
          "-1 for any other k.");
}

}  // namespace avsplat::python
