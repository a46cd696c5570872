// Python bindings of the prediction .npz reader (predictions/prediction_npz.h): the layout's one
// reader, which `avsplat fuse`, FusionStream users and avsplat.dask share.
#include "module.h"
#include "numpy_arrays.h"
#include "paths.h"
#include "release_gil.h"

#include "avsplat/predictions/prediction_npz.h"

#include <pybind11/stl.h>

#include <string>
#include <vector>

namespace avsplat::python {

void bind_predictions(py::module_& m) {
    py::class_<PredictionSamples>(m, "PredictionSamples", R"doc(
The samples a prediction .npz holds, ready for fusion (see read_prediction_npz).

Attributes
----------
kind : str
    'gaussians' (per-pixel Gaussians, or point maps turned into Gaussians) or 'features'
    (raw feature vectors for fuse_voxels).
gaussians : GaussianCloud or None
    kind 'gaussians': one Gaussian per valid pixel, in pixel order, with the file's confidence.
positions : (n, 3) float32 ndarray or None
    kind 'features': the valid pixels' points.
features : (n, C) float32 ndarray or None
    kind 'features': their feature vectors.
confidence : (n,) float32 ndarray or None
    kind 'features': their confidence, when the file has one.
description : str
    How the file was read, e.g. 'per-pixel Gaussians (2 x 120 x 160, SH degree 0)'.
)doc")
        .def_property_readonly("kind",
                               [](const PredictionSamples& p) {
                                   return p.kind == PredictionSamples::Kind::Gaussians ? "gaussians" : "features";
                               })
        .def_property_readonly("gaussians",
                               [](const PredictionSamples& p) -> py::object {
                                   if (p.kind != PredictionSamples::Kind::Gaussians) return py::none();
                                   return py::cast(p.gaussians);
                               })
        .def_property_readonly("positions",
                               [](const PredictionSamples& p) -> py::object {
                                   if (p.kind != PredictionSamples::Kind::Features) return py::none();
                                   return copy_out(p.positions, {py::ssize_t(p.size()), 3});
                               })
        .def_property_readonly("features",
                               [](const PredictionSamples& p) -> py::object {
                                   if (p.kind != PredictionSamples::Kind::Features) return py::none();
                                   return copy_out(p.features, {py::ssize_t(p.size()), py::ssize_t(p.channels)});
                               })
        .def_property_readonly("confidence",
                               [](const PredictionSamples& p) -> py::object {
                                   if (p.kind != PredictionSamples::Kind::Features || p.confidence.empty())
                                       return py::none();
                                   return copy_out(p.confidence, {py::ssize_t(p.size())});
                               })
        .def_readonly("description", &PredictionSamples::description)
        .def("__len__", &PredictionSamples::size)
        .def("__repr__", [](const PredictionSamples& p) {
            return "PredictionSamples(" + std::to_string(p.size()) + " samples: " + p.description + ")";
        });

    m.def(
        "read_prediction_npz",
        [](const py::object& path, const std::vector<Camera>& cameras) {
            const std::string p = fs_path(path);
            ReleaseGil unlocked;
            return read_prediction_npz(p, cameras);
        },
        py::arg("path"), py::arg("cameras") = std::vector<Camera>{}, R"doc(
Reads a feed-forward model's predictions from a numpy .npz, as ``avsplat fuse`` does.

Arrays, with L the leading shape of ``points``: (S, H, W) for S views of H x W pixels, or (N,)
for a plain point set; any integer or float dtype is read as float32:

- ``points`` L x 3: world positions (required)
- ``valid`` L: optional; pixels where it is 0 / False are left out
- ``confidence`` L: optional
- ``colors`` L x 3: optional RGB in [0, 1]
- ``normals`` L x 3: optional (point maps only)

then one of, in this order of precedence: per-pixel Gaussians (``scales`` L x 3 linear,
``rotations`` L x 4 w, x, y, z, ``opacities`` L in [0, 1], and ``sh`` L x K x 3 or L x 3, or
``colors``); raw ``features`` L x C; or point maps (``points`` and ``colors`` only: one flat
Gaussian per pixel from gaussians_from_point_maps). Other arrays are ignored.

Parameters
----------
path : str or os.PathLike
    The .npz file.
cameras : list of Camera, optional
    One per view, for point maps: Gaussians sized by the pixel footprint (kNN distance without).

Returns
-------
PredictionSamples

Raises
------
FileError
    The file cannot be read, or an array is missing or misshaped (the message names the file and
    the array).
)doc");
}

}  // namespace avsplat::python
