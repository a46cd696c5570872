#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "release_gil.h"

#include "avsplat/sim/simulator.h"

#include <pybind11/stl.h>

#include <sstream>

namespace avsplat::python {

namespace {

std::array<float, 3> as_rgb(const py::handle& obj) {
    const FloatArray a = as_float_array(obj, "background", {3}, "3");
    return {a.data()[0], a.data()[1], a.data()[2]};
}

// The pixel grid of a Predictions (S, H, W) or of a GroundTruthImage (H, W).
std::vector<py::ssize_t> grid(const Predictions& p) { return {p.views, p.height, p.width}; }
std::vector<py::ssize_t> grid(const GroundTruthImage& g) { return {g.height, g.width}; }

// A property getter returning a numpy view of the per-pixel member `field` of shape
// grid + (channels,) (grid alone when channels is 0), kept alive by the Python owner.
template <class Owner, class T>
auto pixel_array(std::vector<T> Owner::*field, py::ssize_t channels = 0) {
    return [field, channels](py::object self) {
        auto& owner = self.cast<Owner&>();
        std::vector<py::ssize_t> shape = grid(owner);
        if (channels > 0) shape.push_back(channels);
        return view((owner.*field).data(), std::move(shape), self);
    };
}

// Simulator options with the camera rig set (views on the arc, image size, field of view,
// held-out target views) and every other field at its default.
SimulatorOptions camera_rig(int views, int width, int height, double fov_y, int target_views) {
    SimulatorOptions o;
    o.views = views;
    o.width = width;
    o.height = height;
    o.fov_y = fov_y;
    o.target_views = target_views;
    return o;
}

}  // namespace

void bind_simulator(py::module_& m) {
    py::enum_<SceneObject>(m, "SceneObject", "Objects of the default scene (values of object_id).")
        .value("Background", SceneObject::Background)
        .value("Ground", SceneObject::Ground)
        .value("Wall", SceneObject::Wall)
        .value("Bunny", SceneObject::Bunny)
        .value("Sphere", SceneObject::Sphere);

    py::class_<Predictions>(m, "Predictions", R"doc(
Simulated per-pixel predictions of S views of H x W pixels (see ``simulate_predictions``).

Array properties are numpy views of the C++ storage; entries of invalid pixels are 0 (colour:
the background).

Attributes
----------
points : (S, H, W, 3) float32 ndarray
    Predicted world points (misregistered, noisy).
colors : (S, H, W, 3) float32 ndarray
    RGB in [0, 1] the model saw (supersampled).
confidence : (S, H, W) float32 ndarray
    A logit; higher is more reliable.
true_error : (S, H, W) float32 ndarray
    Distance from the predicted to the true point.
true_points : (S, H, W, 3) float32 ndarray
    The true hit of the pixel-centre ray.
normals : (S, H, W, 3) float32 ndarray
    Predicted unit normals facing the camera.
valid : (S, H, W) bool ndarray
    The pixel-centre ray hits the scene.
object_id : (S, H, W) int32 ndarray
    SceneObject of the true hit (-1: none).
cameras : list of Camera
    S predicted (misregistered) cameras, which unproject the point maps.
true_cameras : list of Camera
    The S cameras that took the views.
target_cameras : list of Camera
    Held-out cameras between input views.
features : (S, H, W, C) float32 ndarray
    Raw Gaussian-head features (``feature_layout``: opacity logit, log scale x3, quaternion,
    SH degree 0), with their noise.
feature_layout : FeatureLayout
    The layout of ``features`` (``decode_gaussians``).
uncertainty : (S, H, W) float32 ndarray
    Where a model is unsure, u in [1, 5] (0: invalid).
appearance_error : (S, H, W) float32 ndarray
    Mean absolute difference of the decoded feature colour and the true diffuse colour.
view_gains : (S, 3) float32 ndarray
    RGB exposure x white-balance gains of each view.
confidence_spearman : float
    Spearman's rho of the confidence against -(e_geo / (0.01 depth) + appearance_error / 0.05)
    over the valid pixels.)doc")
        .def_readonly("views", &Predictions::views)
        .def_readonly("height", &Predictions::height)
        .def_readonly("width", &Predictions::width)
        .def_property_readonly("points", pixel_array(&Predictions::points, 3))
        .def_property_readonly("colors", pixel_array(&Predictions::colors, 3))
        .def_property_readonly("confidence", pixel_array(&Predictions::confidence))
        .def_property_readonly("true_error", pixel_array(&Predictions::true_error))
        .def_property_readonly("true_points", pixel_array(&Predictions::true_points, 3))
        .def_property_readonly("normals", pixel_array(&Predictions::normals, 3))
        .def_property_readonly("valid", [](py::object s) {
            // uint8 storage holding 0 / 1 is a valid numpy bool buffer.
            auto& p = s.cast<Predictions&>();
            return py::array(py::dtype::of<bool>(), grid(p), {},
                             reinterpret_cast<const bool*>(p.valid.data()), s);
        })
        .def_property_readonly("object_id", pixel_array(&Predictions::object_id))
        .def_readonly("cameras", &Predictions::cameras)
        .def_readonly("true_cameras", &Predictions::true_cameras)
        .def_readonly("target_cameras", &Predictions::target_cameras)
        .def_property_readonly("features", [](py::object self) {
            auto& p = self.cast<Predictions&>();
            return view(p.features.data(), {p.views, p.height, p.width, py::ssize_t(p.feature_layout.channels())}, self);
        })
        .def_readonly("feature_layout", &Predictions::feature_layout)
        .def_property_readonly("uncertainty", pixel_array(&Predictions::uncertainty))
        .def_property_readonly("appearance_error", pixel_array(&Predictions::appearance_error))
        .def_property_readonly("view_gains", [](py::object self) {
            auto& p = self.cast<Predictions&>();
            return view(p.view_gains.data(), {p.views, 3}, self);
        })
        .def_readonly("confidence_spearman", &Predictions::confidence_spearman)
        .def("decoded_gaussians", [](const Predictions& p) {
                ReleaseGil release;
                return p.decoded_gaussians();
            }, R"doc(
One Gaussian per valid pixel, in pixel order, decoded from the raw head features.

That is ``decode_gaussians(points[valid], features[valid], feature_layout,
confidence[valid])``: the per-pixel Gaussians with every error model, the attribute noise
included.

Returns
-------
GaussianCloud)doc")
        .def(
            "gaussians",
            [](py::object self, const py::kwargs& options) {
                // The same function as gaussians_from_point_maps, so the keyword arguments and
                // their defaults are defined once.
                const py::object fn = py::module_::import("avsplat._avsplat").attr("gaussians_from_point_maps");
                return fn(self.attr("points"), self.attr("colors"), self.attr("confidence"),
                          self.attr("cameras"), self.attr("normals"), self.attr("valid"), **options)
                    .cast<GaussianCloud>();
            },
            R"doc(
One flat Gaussian per valid pixel, in pixel order, from the point maps.

``gaussians_from_point_maps`` with the predicted cameras (scale from the pixel footprint), the
predicted normals, and opacity and confidence channel from the confidence.

Parameters
----------
**kwargs
    Those of ``gaussians_from_point_maps`` (k, thickness, scale_multiplier, max_stretch,
    min_scale, confidence_mapping, ...).

Returns
-------
GaussianCloud)doc")
        .def("__repr__", [](const Predictions& p) {
            std::size_t valid = 0;
            for (auto v : p.valid) valid += v != 0;
            std::ostringstream os;
            os << "Predictions(views=" << p.views << ", " << p.width << "x" << p.height
               << ", valid=" << valid << "/" << p.valid.size() << ")";
            return os.str();
        });

    py::class_<GroundTruthImage>(m, "GroundTruthImage", R"doc(
A ground-truth render of the default scene (see ``ground_truth``); numpy views, H x W.

Attributes
----------
color : (H, W, 3) float32 ndarray
    Mean of the supersample^2 samples (background where they miss).
alpha : (H, W) float32 ndarray
    Fraction of the samples that hit the scene.
depth : (H, W) float32 ndarray
    Camera-space z of the pixel-centre hit, 0 where none.
normals : (H, W, 3) float32 ndarray
    Unit world normal facing the camera, 0 where none.
object_id : (H, W) int32 ndarray
    SceneObject of the centre hit (-1: none).)doc")
        .def_readonly("width", &GroundTruthImage::width)
        .def_readonly("height", &GroundTruthImage::height)
        .def_property_readonly("color", pixel_array(&GroundTruthImage::color, 3))
        .def_property_readonly("alpha", pixel_array(&GroundTruthImage::alpha))
        .def_property_readonly("depth", pixel_array(&GroundTruthImage::depth))
        .def_property_readonly("normals", pixel_array(&GroundTruthImage::normals, 3))
        .def_property_readonly("object_id", pixel_array(&GroundTruthImage::object_id))
        .def("__repr__", [](const GroundTruthImage& g) {
            return "GroundTruthImage(" + std::to_string(g.width) + "x" + std::to_string(g.height) + ")";
        });

    const SimulatorOptions d;
    m.def(
        "simulate_predictions",
        [](int views, int width, int height, double fov_y, int target_views, double pose_noise_rot_deg,
           double pose_noise_trans, double depth_noise, bool flying_pixels, double confidence_noise,
           int supersample, const Float3& background, std::uint64_t seed, double footprint_sigma,
           double exposure_sigma, double white_balance_sigma, double specular, double mixed_pixel_radius,
           double attribute_noise, std::optional<double> confidence_rho) {
            SimulatorOptions o = camera_rig(views, width, height, fov_y, target_views);
            o.pose_noise_rot_deg = pose_noise_rot_deg;
            o.pose_noise_trans = pose_noise_trans;
            o.depth_noise = depth_noise;
            o.flying_pixels = flying_pixels;
            o.confidence_noise = confidence_noise;
            o.supersample = supersample;
            o.background = as_rgb(background);
            o.seed = seed;
            o.footprint_sigma = footprint_sigma;
            o.exposure_sigma = exposure_sigma;
            o.white_balance_sigma = white_balance_sigma;
            o.specular = specular;
            o.mixed_pixel_radius = mixed_pixel_radius;
            o.attribute_noise = attribute_noise;
            o.confidence_rho = confidence_rho;
            ReleaseGil release;
            return simulate_predictions(o);
        },
        py::arg("views") = d.views, py::arg("width") = d.width, py::arg("height") = d.height,
        py::arg("fov_y") = d.fov_y, py::arg("target_views") = d.target_views,
        py::arg("pose_noise_rot_deg") = d.pose_noise_rot_deg, py::arg("pose_noise_trans") = d.pose_noise_trans,
        py::arg("depth_noise") = d.depth_noise, py::arg("flying_pixels") = d.flying_pixels,
        py::arg("confidence_noise") = d.confidence_noise, py::arg("supersample") = d.supersample,
        py::arg("background") = py::make_tuple(0.0, 0.0, 0.0), py::arg("seed") = d.seed,
        py::arg("footprint_sigma") = d.footprint_sigma, py::arg("exposure_sigma") = d.exposure_sigma,
        py::arg("white_balance_sigma") = d.white_balance_sigma, py::arg("specular") = d.specular,
        py::arg("mixed_pixel_radius") = d.mixed_pixel_radius, py::arg("attribute_noise") = d.attribute_noise,
        py::arg("confidence_rho") = py::none(),
        R"doc(
Simulate feed-forward predictions of the embedded default scene.

The scene holds a bunny, a sphere, a textured ground and a brick wall. Seeded and
deterministic. The error models of real predictions are off by default; the C++ header
``sim/simulator.h`` documents each.

Parameters
----------
views, width, height : int
    S input views of H x W pixels.
fov_y : float
    Vertical field of view in degrees.
target_views : int
    Held-out views between input views (<= views - 1).
pose_noise_rot_deg : float
    RMS rotation error of each view's pose (misregistration), degrees.
pose_noise_trans : float
    RMS translation error of each view's pose.
depth_noise : float
    Relative per-pixel depth noise (grows x3 towards grazing angles).
flying_pixels : bool
    Smear depth across depth discontinuities.
confidence_noise : float
    Std of the noise on the confidence logit log(0.01 depth / error).
supersample : int
    Colour samples per pixel side.
background : tuple of 3 float
    RGB where rays hit nothing.
seed : int
    Any uint64; equal seeds give bit-identical results.
footprint_sigma : float
    Optical blur: the pixel square convolved with a Gaussian of this std in pixels (0..8).
exposure_sigma : float
    Per-view exposure gain 2^(exposure_sigma n), in stops.
white_balance_sigma : float
    Per-view red and blue gains exp(white_balance_sigma n) against green.
specular : float
    Strength 0..1 of a highlight on the sphere and a grazing sheen on the bunny.
mixed_pixel_radius : float
    Colours within this radius (pixels) of a depth edge mix the two surfaces.
attribute_noise : float
    Std of the head-feature noise (colour; x5 opacity logit; x2 log scale) at uncertainty 1,
    times ``Predictions.uncertainty`` (far, grazing, textureless, edge).
confidence_rho : float, optional
    None (the default confidence) or the target Spearman rho in [-1, 1] of the confidence with
    the negative total error (geometric + appearance).

Returns
-------
Predictions)doc");

    m.def(
        "input_cameras",
        [](int views, int width, int height, double fov_y) {
            return input_cameras(camera_rig(views, width, height, fov_y, 0));
        },
        py::arg("views") = d.views, py::arg("width") = d.width, py::arg("height") = d.height,
        py::arg("fov_y") = d.fov_y, "The simulator's input cameras (true poses), in arc order.");

    m.def(
        "target_cameras",
        [](int views, int width, int height, double fov_y, int target_views) {
            return target_cameras(camera_rig(views, width, height, fov_y, target_views));
        },
        py::arg("views") = d.views, py::arg("width") = d.width, py::arg("height") = d.height,
        py::arg("fov_y") = d.fov_y, py::arg("target_views") = d.target_views,
        "The held-out target cameras, each midway between two neighbouring input views.");

    m.def(
        "ground_truth",
        [](const Camera& camera, int supersample, const Float3& background, double footprint_sigma,
           double specular) {
            SimulatorOptions o;
            o.supersample = supersample;
            o.background = as_rgb(background);
            o.footprint_sigma = footprint_sigma;
            o.specular = specular;
            ReleaseGil release;
            return ground_truth(camera, o);
        },
        py::arg("camera"), py::arg("supersample") = d.supersample,
        py::arg("background") = py::make_tuple(0.0, 0.0, 0.0), py::arg("footprint_sigma") = d.footprint_sigma,
        py::arg("specular") = d.specular, R"doc(
Render the default scene's ground truth from a camera by ray casting.

supersample^2 stratified colour samples per pixel. `footprint_sigma` and `specular` are the
error models of ``simulate_predictions`` (the optical blur, the view-dependent term for this
camera's direction), so a target view is rendered with the same optics as the inputs.

Parameters
----------
camera : Camera
    The view.
supersample : int
    Colour samples per pixel side.
background : tuple of 3 float
    RGB where the samples miss.
footprint_sigma, specular : float
    As ``simulate_predictions``.

Returns
-------
GroundTruthImage)doc");

    m.def(
        "scene_color",
        [](const ArrayLike& points, const ArrayLike& objects) {
            const FloatArray p = as_float_array(points, "points", {-1, 3}, "N, 3");
            const py::ssize_t n = p.shape(0);
            const auto ids = as_contiguous<std::int32_t>(objects, "objects", "int");
            if (!ids || ids.ndim() != 1 || ids.shape(0) != n)
                throw py::value_error("objects: expected an int array of shape (N,)");
            std::vector<float> out(3 * static_cast<std::size_t>(n));
            for (py::ssize_t i = 0; i < n; ++i) {
                const Eigen::Vector3d q(p.data()[3 * i], p.data()[3 * i + 1], p.data()[3 * i + 2]);
                const Eigen::Vector3f c = scene_color(q, static_cast<SceneObject>(ids.data()[i]));
                std::copy_n(c.data(), 3, &out[3 * i]);
            }
            return move_out(std::move(out), {n, 3});
        },
        py::arg("points"), py::arg("objects"),
        "Ground-truth texture colour of points (N, 3) on objects (N,) int (SceneObject values 0..3)\n"
        "-> (N, 3) float32 RGB in [0, 1].");

    m.def(
        "bunny_mesh",
        [] {
            TriangleMesh mesh = bunny_mesh();
            const auto nv = static_cast<py::ssize_t>(mesh.num_vertices());
            const auto nf = static_cast<py::ssize_t>(mesh.num_triangles());
            std::vector<double> v = std::move(mesh.vertices);
            std::vector<std::int32_t> f = std::move(mesh.triangles);
            return py::make_tuple(move_out(std::move(v), {nv, 3}), move_out(std::move(f), {nf, 3}));
        },
        "The embedded Stanford bunny as placed in the scene: (vertices (V, 3) float64, triangles\n"
        "(F, 3) int32). Public domain, Stanford 3D Scanning Repository via npm's 'bunny'.");
}

}  // namespace avsplat::python
