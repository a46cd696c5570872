// simplify (avsplat/reduce/simplify.h): a Gaussian budget by merging or voxel fusion.
#include "module.h"
#include "typed_args.h"
#include "progress_arg.h"
#include "release_gil.h"

#include "avsplat/core/names.h"
#include "avsplat/reduce/names.h"
#include "avsplat/reduce/simplify.h"

#include <pybind11/stl.h>

#include <cmath>
#include <sstream>

namespace avsplat::python {

namespace py = pybind11;

namespace {

SimplifyResult simplify_py(const GaussianCloud& cloud, const OptionalInt& target_count, const OptionalFloat& ratio,
                           const OptionalFloat& max_error, const OptionalCameras& cameras, const std::string& method,
                           const OptionalCallable& progress) {
    SimplifyOptions o;
    if (!target_count.is_none()) {
        if (py::isinstance<py::bool_>(target_count) || !py::isinstance<py::int_>(target_count))
            throw py::type_error("target_count: expected an int or None");
        const long long t = target_count.cast<long long>();
        if (t < 1) throw py::value_error("target_count: must be >= 1, got " + std::to_string(t));
        o.target_count = std::size_t(t);
    }
    if (!ratio.is_none()) o.ratio = ratio.cast<double>();
    if (!max_error.is_none()) o.max_error = max_error.cast<double>();
    const int budgets = int(o.target_count.has_value()) + int(o.ratio.has_value()) + int(o.max_error.has_value());
    if (budgets != 1)
        throw py::value_error("simplify: give exactly one of target_count, ratio and max_error");
    if (o.ratio && !(*o.ratio > 0.0 && *o.ratio <= 1.0))
        throw py::value_error("ratio: must be in (0, 1], got " + py::repr(ratio).cast<std::string>());
    if (o.max_error && !(*o.max_error > 0.0 && std::isfinite(*o.max_error)))
        throw py::value_error("max_error: must be finite and > 0, got " + py::repr(max_error).cast<std::string>());
    o.method = parse_simplify_method(method, "method");
    std::vector<Camera> cams;
    if (!cameras.is_none()) {
        if (py::isinstance<Camera>(cameras)) cams.push_back(cameras.cast<Camera>());
        else {
            try {
                cams = cameras.cast<std::vector<Camera>>();
            } catch (const py::cast_error&) {
                throw py::type_error("cameras: expected a Camera, a list of Camera or None");
            }
        }
    }
    if (o.max_error && cams.empty()) throw py::value_error("max_error: needs cameras to measure the error at");
    const PythonProgress reporting(progress);
    ReleaseGil release(cloud);
    return simplify(cloud, o, cams);
}

}  // namespace

void bind_simplify(py::module_& m) {
    py::class_<SimplifyResult>(m, "SimplifyResult", "A cloud simplified to a budget of Gaussians, and how.")
        .def_readonly("cloud", &SimplifyResult::cloud, "the simplified GaussianCloud")
        .def_readonly("input_count", &SimplifyResult::input_count, "Gaussians given")
        .def_readonly("target_count", &SimplifyResult::target_count,
                      "Gaussians asked for (with max_error: the count the search settled on)")
        .def_readonly("output_count", &SimplifyResult::output_count, "Gaussians in cloud")
        .def_property_readonly("method", [](const SimplifyResult& r) { return to_string(r.method); },
                               "'merge' or 'voxel'")
        .def_readonly("voxel_size", &SimplifyResult::voxel_size, "the voxel size the voxel method used (nan for merge)")
        .def_readonly("iterations", &SimplifyResult::iterations,
                      "merge rounds (merge), or voxel sizes the bisection tried (voxel)")
        .def_readonly("error", &SimplifyResult::error,
                      "RMSE of rendered RGB (in [0, 1]) against the input at the cameras; nan without cameras")
        .def_readonly("searches", &SimplifyResult::searches,
                      "simplifications the search on the count tried (max_error); 1 otherwise")
        .def("__repr__", [](const SimplifyResult& r) {
            std::ostringstream os;
            os << "SimplifyResult(method='" << to_string(r.method) << "', " << r.input_count << " -> "
               << r.output_count << " Gaussians";
            if (r.method == SimplifyMethod::Voxel && std::isfinite(r.voxel_size)) os << ", voxel_size=" << r.voxel_size;
            if (std::isfinite(r.error)) os << ", error=" << r.error;
            os << ")";
            return os.str();
        });

    m.def("simplify", &simplify_py, py::arg("cloud"), py::arg("target_count") = py::none(),
          py::arg("ratio") = py::none(), py::arg("max_error") = py::none(), py::arg("cameras") = py::none(),
          py::arg("method") = to_string(SimplifyOptions{}.method), py::kw_only(), py::arg("progress") = py::none(),
          R"doc(
Reduce a GaussianCloud to a budget of Gaussians with the least image error.

Give exactly one budget: `target_count`, `ratio` or `max_error`.

Parameters
----------
cloud : GaussianCloud
    N Gaussians.
target_count : int, optional
    Gaussians to keep, >= 1 (a count >= len(cloud) returns the input).
ratio : float, optional
    Keep round(ratio * len(cloud)) Gaussians (at least 1), ratio in (0, 1].
max_error : float, optional
    The fewest Gaussians whose renders at `cameras` stay within this RMSE of the input's
    renders (RGB in [0, 1], over all pixels, channels and cameras), found by bisection on
    log(count); > 0.
cameras : Camera or list of Camera, optional
    Required with `max_error`; otherwise, when given, the result's ``error`` is measured there.
method : {"merge", "voxel"}
    "merge": rounds of greedy pairwise merging of nearby Gaussians by moment matching,
    cheapest pair first, at most 40 % of the Gaussians per round, until the count is met
    exactly; the cost weighs the change of shape, the ink lost to the opacity cap, the colour
    difference and the change of the rendered field (docs/design/reduction.md). "voxel":
    occupancy-guided fusion (shape "moment") at the voxel size found by bisection to give the
    count within 2 %; a cloud without confidence gets logit(opacity) as its confidence.
progress : callable, optional
    Called as progress(done, total) from the calling thread (the GIL taken only for the call):
    with a count or ratio, the Gaussians removed so far of those to remove, after each merge
    round (the voxel method reports at the start and the end); with `max_error`, the
    simplifications tried of at most 13, ending at (13, 13) when the search stops earlier.
    First (0, total), done never decreases, last (total, total). An exception it raises stops
    the work and is raised from here. The result does not depend on it.

Returns
-------
SimplifyResult
    ``cloud``, ``input_count``, ``target_count``, ``output_count``, ``method``,
    ``voxel_size``, ``iterations``, ``error``.

Raises
------
ValueError
    For an invalid cloud (naming the field and index), a bad budget, method or camera, or
    `max_error` without `cameras`.

Notes
-----
Deterministic: the same result for any thread count and any order of the input.)doc");
}

}  // namespace avsplat::python
