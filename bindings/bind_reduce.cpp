// Python bindings of the reduction operators prune (reduce/prune.h) and reduce_sh
// (reduce/reduce_sh.h).
#include "module.h"
#include "typed_args.h"
#include "progress_arg.h"
#include "release_gil.h"

#include "avsplat/core/names.h"
#include "avsplat/reduce/prune.h"
#include "avsplat/reduce/reduce_sh.h"

#include <pybind11/stl.h>

#include <optional>
#include <string>
#include <vector>

namespace avsplat::python {

namespace py = pybind11;

void bind_reduce(py::module_& m) {
    py::class_<PruneResult>(m, "PruneResult", R"doc(
What prune kept and removed. Each removed Gaussian is counted once, under the first reason.

Attributes
----------
cloud : GaussianCloud
    The kept Gaussians, in their input order.
kept, removed : int
    Counts of kept and removed Gaussians.
degenerate : int
    Invalid: a non-finite field, a negative scale, a zero quaternion, opacity outside [0, 1].
low_opacity : int
    Opacity below ``min_opacity``.
invisible : int
    Contribution below ``min_contribution`` (or none) at every pixel of every camera.
cameras : int
    Cameras the contributions were measured at.
max_removed_contribution : float
    The largest ``contribution_max`` among the invisible ones (0 by default).)doc")
        .def_readonly("cloud", &PruneResult::cloud)
        .def_readonly("kept", &PruneResult::kept)
        .def_readonly("removed", &PruneResult::removed)
        .def_readonly("degenerate", &PruneResult::degenerate)
        .def_readonly("low_opacity", &PruneResult::low_opacity)
        .def_readonly("invisible", &PruneResult::invisible)
        .def_readonly("cameras", &PruneResult::cameras)
        .def_readonly("max_removed_contribution", &PruneResult::max_removed_contribution)
        .def("summary", &PruneResult::summary, "One line: kept, removed and the counts by reason.")
        .def("__repr__", [](const PruneResult& r) { return "PruneResult(" + r.summary() + ")"; });

    const RenderOptions kRender{};
    m.def(
        "prune",
        [](const GaussianCloud& cloud, const OptionalCameras& cameras, float min_opacity,
           std::optional<float> min_contribution, const std::string& precision,
           const std::array<float, 3>& background, bool antialiased, float low_pass, float alpha_threshold,
           float transmittance_stop, float extent_sigma, const OptionalCallable& progress) {
            std::vector<Camera> cams;
            if (py::isinstance<Camera>(cameras)) {
                cams.push_back(cameras.cast<Camera>());
            } else if (!cameras.is_none()) {
                try {
                    cams = cameras.cast<std::vector<Camera>>();
                } catch (const py::cast_error&) {
                    throw py::value_error("cameras: expected None, a Camera or a list of Cameras");
                }
            }
            PruneParams p;
            p.min_opacity = min_opacity;
            p.min_contribution = min_contribution;
            p.render.precision = parse_precision(precision);
            p.render.background = background;
            p.render.antialiased = antialiased;
            p.render.low_pass = low_pass;
            p.render.alpha_threshold = alpha_threshold;
            p.render.transmittance_stop = transmittance_stop;
            p.render.extent_sigma = extent_sigma;
            const PythonProgress reporting(progress);
            ReleaseGil release(cloud);
            return prune(cloud, cams, p);
        },
        py::arg("cloud"), py::arg("cameras") = py::none(), py::arg("min_opacity") = PruneParams{}.min_opacity,
        py::arg("min_contribution") = py::none(), py::arg("precision") = to_string(kRender.precision),
        py::arg("background") = kRender.background, py::arg("antialiased") = kRender.antialiased,
        py::arg("low_pass") = kRender.low_pass, py::arg("alpha_threshold") = kRender.alpha_threshold,
        py::arg("transmittance_stop") = kRender.transmittance_stop, py::arg("extent_sigma") = kRender.extent_sigma,
        py::kw_only(), py::arg("progress") = py::none(),
        R"doc(
Remove the Gaussians that cannot change an image.

Parameters
----------
cloud : GaussianCloud
    N Gaussians; invalid ones are removed and counted as degenerate.
cameras : Camera or list of Camera, optional
    Also remove the Gaussians that no pixel of any of them composites (measured with
    ``render(..., gaussian_contributions=True)``).
min_opacity : float
    Remove opacity < min_opacity, in [0, 1] (default 1/255, the alpha threshold).
min_contribution : float, optional
    None (default): remove only Gaussians with no contribution anywhere; the renders from
    `cameras` stay bit-identical. A float c in [0, 1]: remove those whose alpha T stays below c
    at every pixel; each pixel then changes by at most D (the sum of the removed alpha T at the
    pixel + the pixel's stop transmittance), D the colour spread (reduce/prune.h).
precision, background, antialiased, low_pass, alpha_threshold, transmittance_stop, extent_sigma
    The render options the contributions are measured with (as ``render``, CPU back end); use
    those the pruned cloud will be rendered with.
progress : callable, optional
    Called as progress(done, total) with the cameras rendered so far and their number, from
    the calling thread (the GIL taken only for the call): first (0, total), then after each
    camera. An exception it raises stops the work and is raised from here.

Returns
-------
PruneResult
    ``cloud`` and the counts.

Raises
------
ValueError
    For inconsistent array sizes or a bad argument, naming it.

Notes
-----
The GIL is released.)doc");

    py::class_<ReduceShResult>(m, "ReduceShResult", R"doc(
What reduce_sh kept.

Attributes
----------
cloud : GaussianCloud
    The Gaussians with ``sh_degree`` = the chosen degree.
sh_degree : int
    The chosen degree; ``sh_degree_before`` is the input's.
max_error_bound : float
    Max over Gaussians and channels of the dropped bands' bound, in colour units.
bytes_saved : int
    SH bytes saved (float32 coefficients, in memory and in a 3DGS PLY).
gaussians_by_degree : list of 4 int
    Counts of Gaussians whose own smallest degree meeting ``max_error`` is k.)doc")
        .def_readonly("cloud", &ReduceShResult::cloud)
        .def_readonly("sh_degree", &ReduceShResult::sh_degree)
        .def_readonly("sh_degree_before", &ReduceShResult::sh_degree_before)
        .def_readonly("max_error_bound", &ReduceShResult::max_error_bound)
        .def_readonly("bytes_saved", &ReduceShResult::bytes_saved)
        .def_property_readonly("gaussians_by_degree",
                               [](const ReduceShResult& r) {
                                   return std::vector<std::size_t>(r.gaussians_by_degree.begin(),
                                                                   r.gaussians_by_degree.end());
                               })
        .def("summary", &ReduceShResult::summary, "One line: degrees, bound, bytes saved, per-Gaussian degrees.")
        .def("__repr__", [](const ReduceShResult& r) { return "ReduceShResult(" + r.summary() + ")"; });

    m.def(
        "reduce_sh",
        [](const GaussianCloud& cloud, double max_error, std::optional<int> degree) {
            if (degree && *degree < 0)
                throw py::value_error("degree: must be None or in 0.." + std::to_string(cloud.sh_degree) + ", got " +
                                      std::to_string(*degree));
            ReleaseGil release(cloud);
            return reduce_sh(cloud, max_error, degree ? *degree : -1);
        },
        py::arg("cloud"), py::arg("max_error") = 1.0 / 255.0, py::arg("degree") = py::none(),
        R"doc(
Drop the SH bands whose share of the colour is at most max_error in every view direction.

Parameters
----------
cloud : GaussianCloud
    N Gaussians.
max_error : float
    Largest colour change allowed, >= 0 (1/255: one 8-bit level).
degree : int, optional
    None: the smallest degree meeting `max_error` for every Gaussian; an int in
    0..cloud.sh_degree forces it (the bound achieved is reported).

Returns
-------
ReduceShResult
    ``cloud``, ``sh_degree``, ``max_error_bound``, ``bytes_saved``, ``gaussians_by_degree``.

Raises
------
ValueError
    For an invalid cloud or argument.

Notes
-----
The bound of band l per channel is sqrt((2l + 1) / (4 pi)) norm(c_l) (Cauchy-Schwarz and the
addition theorem), the dropped bands' bounds add, and clamping at 0 cannot enlarge the error,
so no rendered pixel changes by more than ``max_error_bound`` (plus float32 rounding).)doc");
}

}  // namespace avsplat::python
