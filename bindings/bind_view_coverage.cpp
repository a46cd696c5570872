#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "release_gil.h"

#include "avsplat/assist/view_coverage.h"

#include <pybind11/stl.h>

#include <sstream>

namespace avsplat::python {

namespace {

ViewCoverage select_views(const ArrayLike& points, double voxel_size, const OptionalInt& budget,
                          double min_gain, const OptionalArrayLike& confidence, double min_confidence,
                          const OptionalArrayLike& valid) {
    const FloatArray converted = as_contiguous<float>(points, "points", "float");
    if (!converted || (converted.ndim() != 4 && converted.ndim() != 3))
        throw py::value_error("points: expected shape (S, H, W, 3) or (S, N, 3)");
    const bool image = converted.ndim() == 4;
    const py::ssize_t s = converted.shape(0), h = image ? converted.shape(1) : 1,
                      w = image ? converted.shape(2) : converted.shape(1);
    const FloatArray p = image ? as_float_array(converted, "points", {s, h, w, 3}, "S, H, W, 3")
                               : as_float_array(converted, "points", {s, w, 3}, "S, N, 3");
    FloatArray c;
    if (!confidence.is_none())
        c = image ? as_float_array(confidence, "confidence", {s, h, w}, "S, H, W")
                  : as_float_array(confidence, "confidence", {s, w}, "S, N");
    ArrayOf<std::uint8_t> v;
    if (!valid.is_none())
        v = image ? as_array<std::uint8_t>(valid, "valid", {s, h, w}, "S, H, W", "bool")
                  : as_array<std::uint8_t>(valid, "valid", {s, w}, "S, N", "bool");
    ViewCoverageOptions o;
    o.voxel_size = voxel_size;
    if (!budget.is_none()) {
        const long long b = budget.cast<long long>();
        if (b < 1) throw py::value_error("budget: must be >= 1 or None, got " + std::to_string(b));
        o.budget = static_cast<std::size_t>(b);
    }
    o.min_gain = min_gain;
    o.min_confidence = min_confidence;
    ReleaseGil release;
    return select_views_by_coverage(p.data(), confidence.is_none() ? nullptr : c.data(),
                                    valid.is_none() ? nullptr : v.data(), int(s), int(h),
                                    int(w), o);
}

}  // namespace

void bind_view_coverage(py::module_& m) {
    py::class_<ViewCoverage>(m, "ViewCoverage",
                             "The views chosen by greedy coverage, in pick order, with the voxels each added.")
        .def_property_readonly(
            "order", [](const ViewCoverage& r) { return copy_out(r.order, {py::ssize_t(r.order.size())}); },
            "(K,) int64: the chosen views in the order greedy picked them")
        .def_property_readonly(
            "gains", [](const ViewCoverage& r) { return copy_out(r.gains, {py::ssize_t(r.gains.size())}); },
            "(K,) int64: voxels each pick added to those already covered")
        .def_property_readonly(
            "coverage",
            [](const ViewCoverage& r) { return copy_out(r.coverage, {py::ssize_t(r.coverage.size())}); },
            "(K,) int64: voxels covered after each pick")
        .def_readonly("total_voxels", &ViewCoverage::total_voxels,
                      "voxels that all views cover together (the denominator of min_gain)")
        .def_readonly("points_used", &ViewCoverage::points_used,
                      "pixels that counted (confidence above min_confidence)")
        .def("__repr__", [](const ViewCoverage& r) {
            std::ostringstream os;
            os << "ViewCoverage(views=" << r.order.size() << ", covered=" << (r.coverage.empty() ? 0 : r.coverage.back())
               << " of " << r.total_voxels << " voxels)";
            return os.str();
        });

    m.def("select_views_by_coverage", &select_views, py::arg("points"), py::arg("voxel_size"),
          py::arg("budget") = py::none(), py::arg("min_gain") = 0.0, py::arg("confidence") = py::none(),
          py::arg("min_confidence") = 0.0, py::arg("valid") = py::none(),
          R"doc(
Order views by the voxels they add to those already covered (lazy greedy coverage).

A view covers the voxels of side `voxel_size` its points fall in (the voxel rule fusion uses).
Greedy picks, at each step, the view that adds the most uncovered voxels (ties to the smaller
index), until `budget` views are chosen or the best view adds fewer than
min_gain * total_voxels. The order is exactly plain greedy's (lazy evaluation only skips work),
so it covers at least (1 - 1/e) of what the best set of the same size covers. Deterministic,
independent of the thread count.

Parameters
----------
points : array_like, shape (S, H, W, 3) or (S, N, 3)
    Predicted point maps, or points per view.
voxel_size : float
    > 0.
budget : int, optional
    Views to choose; all by default.
min_gain : float
    Stop when the best view adds fewer than min_gain * total_voxels.
confidence : array_like, shape (S, H, W) or (S, N), optional
    Only pixels whose confidence is > `min_confidence` count.
min_confidence : float
    See `confidence`.
valid : array_like of bool, shape (S, H, W) or (S, N), optional
    Only valid pixels count; invalid ones are not read.

Returns
-------
ViewCoverage
    ``order``, ``gains``, ``coverage`` (voxels covered after each pick), ``total_voxels``.

Raises
------
ValueError
    For a bad shape, voxel_size, budget or min_gain, and for a non-finite point or confidence,
    naming its (view, row, col) index.)doc");
}

}  // namespace avsplat::python
