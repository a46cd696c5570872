#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "release_gil.h"

#include "avsplat/core/names.h"
#include "avsplat/metrics/geometry_metrics.h"
#include "avsplat/point_maps/point_maps.h"

#include <pybind11/stl.h>

#include <cstdint>
#include <sstream>

namespace avsplat::python {

namespace {

// The image layout of `points`: (S, H, W, 3), or (N, 3) read as S = 1, H = 1, W = N.
std::vector<py::ssize_t> layout_of(const FloatArray& a) {
    if (a && a.ndim() == 4) return {a.shape(0), a.shape(1), a.shape(2)};
    if (a && a.ndim() == 2) return {1, 1, a.shape(0)};
    throw py::value_error("points: expected shape (S, H, W, 3) or (N, 3)");
}

GaussianCloud from_point_maps(const ArrayLike& points, const ArrayLike& colors,
                              const OptionalArrayLike& confidence, const OptionalCameras& cameras,
                              const OptionalArrayLike& normals, const OptionalArrayLike& valid, int k,
                              int normal_neighbors, bool flat, double thickness,
                              double scale_multiplier, double max_stretch, double min_scale,
                              const std::string& confidence_mapping, double default_opacity) {
    // Converted once (null when not convertible); as_float_array below then copies nothing.
    const FloatArray converted = as_contiguous<float>(points, "points", "float");
    const std::vector<py::ssize_t> l = layout_of(converted);
    const bool image = converted.ndim() == 4;
    const std::vector<py::ssize_t> shape3 = image ? std::vector<py::ssize_t>{l[0], l[1], l[2], 3}
                                                  : std::vector<py::ssize_t>{l[2], 3};
    const std::vector<py::ssize_t> shape1 = image ? std::vector<py::ssize_t>{l[0], l[1], l[2]}
                                                  : std::vector<py::ssize_t>{l[2]};
    const char* dims3 = image ? "S, H, W, 3" : "N, 3";
    const char* dims1 = image ? "S, H, W" : "N";
    const FloatArray p = as_float_array(converted, "points", shape3, dims3);
    const FloatArray c = as_float_array(colors, "colors", shape3, dims3);
    FloatArray conf, nrm;
    if (!confidence.is_none()) conf = as_float_array(confidence, "confidence", shape1, dims1);
    if (!normals.is_none()) nrm = as_float_array(normals, "normals", shape3, dims3);
    ArrayOf<std::uint8_t> v;
    if (!valid.is_none()) v = as_array<std::uint8_t>(valid, "valid", shape1, dims1, "bool");
    std::vector<Camera> cams;
    if (!cameras.is_none()) cams = cameras.cast<std::vector<Camera>>();

    PointMaps m;
    m.views = static_cast<int>(l[0]);
    m.height = static_cast<int>(l[1]);
    m.width = static_cast<int>(l[2]);
    m.points = p.data();
    m.colors = c.data();
    m.confidence = confidence.is_none() ? nullptr : conf.data();
    m.normals = normals.is_none() ? nullptr : nrm.data();
    m.valid = valid.is_none() ? nullptr : v.data();
    PointMapOptions o;
    o.k = k;
    o.normal_neighbors = normal_neighbors;
    o.flat = flat;
    o.thickness = thickness;
    o.scale_multiplier = scale_multiplier;
    o.max_stretch = max_stretch;
    o.min_scale = min_scale;
    o.confidence_mapping = parse_confidence_mapping(confidence_mapping);
    o.default_opacity = default_opacity;
    ReleaseGil release;
    return gaussians_from_point_maps(m, cams, o);
}

FloatArray as_points(const py::handle& obj, const char* arg) {
    return as_float_array(obj, arg, {-1, 3}, "N, 3");
}

}  // namespace

void bind_point_maps(py::module_& m) {
    const PointMapOptions d;
    m.def("gaussians_from_point_maps", &from_point_maps, py::arg("points"), py::arg("colors"),
          py::arg("confidence") = py::none(), py::arg("cameras") = py::none(),
          py::arg("normals") = py::none(), py::arg("valid") = py::none(), py::arg("k") = d.k,
          py::arg("normal_neighbors") = d.normal_neighbors, py::arg("flat") = d.flat,
          py::arg("thickness") = d.thickness, py::arg("scale_multiplier") = d.scale_multiplier,
          py::arg("max_stretch") = d.max_stretch, py::arg("min_scale") = d.min_scale,
          py::arg("confidence_mapping") = to_string(d.confidence_mapping), py::arg("default_opacity") = d.default_opacity,
          R"doc(
Make one flat Gaussian per valid pixel of point maps (VGGT / DUSt3R-style predictions).

Parameters
----------
points : array_like, shape (S, H, W, 3) or (N, 3)
    World points (float32), or a plain point set.
colors : array_like, same shape as `points`
    RGB nominally in [0, 1], made SH degree 0.
confidence : array_like, shape (S, H, W) or (N,), optional
    Its probability under `confidence_mapping` ('logit': sigmoid(c), 'probability': c in
    [0, 1], 'positive': c / (1 + c), c >= 0) is the opacity, and it is kept as the cloud's
    confidence channel.
cameras : list of Camera, optional
    S cameras of size W x H that took the views: the in-plane scale is then
    scale_multiplier * the pixel footprint z / sqrt(fx fy) (z: depth in that camera), stretched
    by 1 / abs(cos) (at most `max_stretch`) along the slant. None: scale_multiplier * the RMS
    distance to the `k` nearest other valid points.
normals : array_like, same shape as `points`, optional
    None: the PCA normal of the `normal_neighbors` nearest points.
valid : array_like of bool, shape (S, H, W) or (N,), optional
    None: all pixels.
k, normal_neighbors : int
    Neighbours for the kNN scale and for the normals.
flat : bool
    False gives isotropic Gaussians.
thickness : float
    The normal axis over the in-plane scale.
scale_multiplier : float
    0.5 (default): the 1-sigma ellipse spans the footprint (kNN: reaches halfway to the
    neighbours), sharp and hole-free; 1: the 3DGS initialisation.
max_stretch : float
    Largest stretch along a slanted surface.
min_scale : float
    Floor of every axis.
confidence_mapping : {"logit", "probability", "positive"}
    How the confidence becomes an opacity.
default_opacity : float
    Opacity when `confidence` is None.

Returns
-------
GaussianCloud
    In pixel order (view, row, column) of the valid pixels.

Raises
------
ValueError
    Naming the argument (shape) or the field and the first bad pixel (value).)doc");

    m.def(
        "remove_statistical_outliers",
        [](const ArrayLike& points, int nb_neighbors, double std_ratio) -> py::tuple {
            if (py::isinstance<GaussianCloud>(points)) {
                const auto& cloud = points.cast<const GaussianCloud&>();
                std::vector<std::size_t> kept;
                {
                    ReleaseGil release(cloud);
                    kept = remove_statistical_outliers(cloud.means.data(), cloud.size(), nb_neighbors, std_ratio);
                }
                std::vector<std::int64_t> idx(kept.begin(), kept.end());
                const py::ssize_t n = static_cast<py::ssize_t>(idx.size());
                return py::make_tuple(select(cloud, kept), move_out(std::move(idx), {n}));
            }
            const FloatArray p = as_points(points, "points");
            std::vector<std::size_t> kept;
            {
                ReleaseGil release;
                kept = remove_statistical_outliers(p.data(), static_cast<std::size_t>(p.shape(0)), nb_neighbors, std_ratio);
            }
            std::vector<float> out(3 * kept.size());
            for (std::size_t j = 0; j < kept.size(); ++j) std::copy_n(p.data() + 3 * kept[j], 3, &out[3 * j]);
            std::vector<std::int64_t> idx(kept.begin(), kept.end());
            const py::ssize_t n = static_cast<py::ssize_t>(idx.size());
            return py::make_tuple(move_out(std::move(out), {n, 3}), move_out(std::move(idx), {n}));
        },
        py::arg("points"), py::arg("nb_neighbors") = 20, py::arg("std_ratio") = 2.0, R"doc(
Statistical outlier removal with Open3D's rule (``remove_statistical_outlier``).

Parameters
----------
points : array_like, shape (N, 3), or GaussianCloud
    float32 points, or a cloud (its means).
nb_neighbors : int
    Neighbours per point, the point itself counted (as Open3D), >= 1.
std_ratio : float
    Keep points whose mean neighbour distance is <= mean + std_ratio * std.

Returns
-------
kept : ndarray, shape (M, 3), float32, or GaussianCloud
    The kept points (or the kept Gaussians).
indices : ndarray, shape (M,), int64
    Their indices, ascending.)doc");

    m.def(
        "compute_point_cloud_distance",
        [](const ArrayLike& source, const ArrayLike& target) {
            const FloatArray s = as_points(source, "source"), t = as_points(target, "target");
            std::vector<double> d;
            {
                ReleaseGil release;
                d = compute_point_cloud_distance(s.data(), static_cast<std::size_t>(s.shape(0)), t.data(),
                                                 static_cast<std::size_t>(t.shape(0)));
            }
            const py::ssize_t n = static_cast<py::ssize_t>(d.size());
            return move_out(std::move(d), {n});
        },
        py::arg("source"), py::arg("target"), R"doc(
For each source point, the distance to the nearest target point.

As Open3D's ``compute_point_cloud_distance``.

Parameters
----------
source : array_like, shape (N, 3), float32
    The points measured.
target : array_like, shape (M, 3), float32
    The points measured against.

Returns
-------
ndarray, shape (N,), float64
    The distances.)doc");

    py::class_<AccuracyCompleteness>(m, "AccuracyCompleteness",
                                     "Accuracy, completeness, chamfer and F-score of a point set.")
        .def_readonly("accuracy", &AccuracyCompleteness::accuracy, "mean distance pred -> gt")
        .def_readonly("completeness", &AccuracyCompleteness::completeness, "mean distance gt -> pred")
        .def_readonly("chamfer", &AccuracyCompleteness::chamfer, "(accuracy + completeness) / 2")
        .def_readonly("precision", &AccuracyCompleteness::precision, "fraction of pred closer than threshold")
        .def_readonly("recall", &AccuracyCompleteness::recall, "fraction of gt closer than threshold")
        .def_readonly("fscore", &AccuracyCompleteness::fscore, "2 P R / (P + R)")
        .def_readonly("threshold", &AccuracyCompleteness::threshold)
        .def("__repr__", [](const AccuracyCompleteness& r) {
            std::ostringstream os;
            os << "AccuracyCompleteness(accuracy=" << r.accuracy << ", completeness=" << r.completeness
               << ", chamfer=" << r.chamfer << ", precision=" << r.precision << ", recall=" << r.recall
               << ", fscore=" << r.fscore << ", threshold=" << r.threshold << ")";
            return os.str();
        });

    m.def(
        "accuracy_completeness",
        [](const ArrayLike& pred, const ArrayLike& gt, double threshold) {
            const FloatArray p = as_points(pred, "pred"), g = as_points(gt, "gt");
            ReleaseGil release;
            return accuracy_completeness(p.data(), static_cast<std::size_t>(p.shape(0)), g.data(),
                                         static_cast<std::size_t>(g.shape(0)), threshold);
        },
        py::arg("pred"), py::arg("gt"), py::arg("threshold"), R"doc(
Accuracy, completeness, Chamfer distance, precision, recall and F-score of a point set.

Accuracy is the mean distance pred -> gt, completeness gt -> pred, chamfer their mean;
precision and recall are the fractions strictly closer than `threshold`; the F-score is as in
DTU and Tanks and Temples.

Parameters
----------
pred : array_like, shape (N, 3), float32
    The reconstruction.
gt : array_like, shape (M, 3), float32
    The ground truth.
threshold : float
    > 0.

Returns
-------
AccuracyCompleteness)doc");

    m.def(
        "chamfer_distance",
        [](const ArrayLike& a, const ArrayLike& b) {
            const FloatArray pa = as_points(a, "a"), pb = as_points(b, "b");
            ReleaseGil release;
            return chamfer_distance(pa.data(), static_cast<std::size_t>(pa.shape(0)), pb.data(),
                                    static_cast<std::size_t>(pb.shape(0)));
        },
        py::arg("a"), py::arg("b"),
        "Symmetric chamfer distance (mean nearest distance a -> b + b -> a) / 2, plain distances.\n"
        "a (N, 3), b (M, 3) float32 -> float.");
}

}  // namespace avsplat::python
