// Python bindings of registration/: Similarity, similarity_from_correspondences, PredictionChunk,
// align_chunks, stitch, fuse_chunks; and the simulator's chunked captures (sim/chunked_capture.h).
#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "release_gil.h"
#include "fusion_params.h"
#include "paths.h"

#include "avsplat/core/names.h"
#include "avsplat/registration/chunk_alignment.h"
#include "avsplat/registration/prediction_chunk.h"
#include "avsplat/registration/similarity.h"
#include "avsplat/registration/stitch.h"
#include "avsplat/sim/chunked_capture.h"

#include <Eigen/Geometry>
#include <pybind11/stl.h>

#include <cmath>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace avsplat::python {

namespace {

py::array_t<double> matrix_out(const Eigen::MatrixXd& m) {
    py::array_t<double> a({static_cast<py::ssize_t>(m.rows()), static_cast<py::ssize_t>(m.cols())});
    for (Eigen::Index i = 0; i < m.rows(); ++i)
        for (Eigen::Index j = 0; j < m.cols(); ++j) a.mutable_at(i, j) = m(i, j);
    return a;
}

Eigen::Matrix3d rotation_in(const py::handle& obj) {
    if (obj.is_none()) return Eigen::Matrix3d::Identity();
    const auto a = as_array<double>(obj, "rotation", {3, 3}, "3, 3", "float");
    Eigen::Matrix3d r;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) r(i, j) = a.data()[3 * i + j];
    return r;
}

Eigen::Vector3d vector_in(const py::handle& obj, const char* arg) {
    if (obj.is_none()) return Eigen::Vector3d::Zero();
    const auto a = as_array<double>(obj, arg, {3}, "3", "float");
    return Eigen::Vector3d(a.data()[0], a.data()[1], a.data()[2]);
}

std::string repr(const Similarity& T) {
    const Eigen::AngleAxisd aa(T.rotation);
    std::ostringstream s;
    s << "Similarity(rotation=" << aa.angle() * 180.0 / 3.14159265358979323846 << " deg, translation=("
      << T.translation[0] << ", " << T.translation[1] << ", " << T.translation[2] << "), scale=" << T.scale << ")";
    return s.str();
}

AlignmentOptions alignment_options(bool pose_graph, double loss_scale, int iterations, int min_correspondences) {
    AlignmentOptions o;
    o.pose_graph = pose_graph;
    o.fit.loss_scale = loss_scale;
    o.fit.iterations = iterations;
    o.min_correspondences = min_correspondences;
    return o;
}

}  // namespace

void bind_registration(py::module_& m) {
    py::class_<Similarity>(m, "Similarity", R"doc(
A similarity transform x -> scale * rotation @ x + translation (rotation proper, scale > 0).

Parameters
----------
rotation : array_like, shape (3, 3), optional
    None: the identity.
translation : array_like, shape (3,), optional
    None: zero.
scale : float

Attributes
----------
rotation : (3, 3) float64 ndarray
translation : (3,) float64 ndarray
scale : float)doc")
        .def(py::init([](const OptionalArrayLike& rotation, const OptionalArrayLike& translation, double scale) {
                 if (!(std::isfinite(scale) && scale > 0.0)) throw py::value_error("scale must be finite and > 0");
                 Similarity T;
                 T.rotation = rotation_in(rotation);
                 T.translation = vector_in(translation, "translation");
                 T.scale = scale;
                 return T;
             }),
             py::arg("rotation") = py::none(), py::arg("translation") = py::none(), py::arg("scale") = 1.0)
        .def_property_readonly("rotation", [](const Similarity& T) { return matrix_out(T.rotation); })
        .def_property_readonly("translation", [](const Similarity& T) {
            py::array_t<double> a(3);
            for (int c = 0; c < 3; ++c) a.mutable_at(c) = T.translation[c];
            return a;
        })
        .def_readonly("scale", &Similarity::scale)
        .def("matrix", [](const Similarity& T) { return matrix_out(T.matrix()); },
             "The 4 x 4 matrix [scale R, t; 0, 1] (float64).")
        .def("inverse", &Similarity::inverse, "The transform that undoes this one.")
        .def("__matmul__", &Similarity::operator*, py::arg("other"), "self @ other: other first, then self.")
        .def(
            "apply",
            [](const Similarity& T, const ArrayLike& points) {
                const auto p = as_array<double>(points, "points", {-1, 3}, "N, 3", "float");
                py::array_t<double> out({p.shape(0), py::ssize_t(3)});
                for (py::ssize_t i = 0; i < p.shape(0); ++i) {
                    const Eigen::Vector3d y = T.apply(Eigen::Vector3d(p.at(i, 0), p.at(i, 1), p.at(i, 2)));
                    for (int c = 0; c < 3; ++c) out.mutable_at(i, c) = y[c];
                }
                return out;
            },
            py::arg("points"), "The points (N, 3) moved by the transform, as float64.")
        .def("__repr__", [](const Similarity& T) { return repr(T); });

    py::class_<SimilarityFit>(m, "SimilarityFit", R"doc(
A fitted similarity (``similarity_from_correspondences``).

Attributes
----------
transform : Similarity
    Maps the source points onto the target points.
rms_residual : float
    Weighted RMS of the distances norm(target - transform(source)), final IRLS weights.
scene_size : float
    The target's RMS spread about its weighted centroid.
effective_count : float
    (sum of final weights)^2 / sum of squared final weights.
iterations : int)doc")
        .def_readonly("transform", &SimilarityFit::transform)
        .def_readonly("rms_residual", &SimilarityFit::rms_residual)
        .def_readonly("scene_size", &SimilarityFit::scene_size)
        .def_readonly("effective_count", &SimilarityFit::effective_count)
        .def_readonly("iterations", &SimilarityFit::iterations)
        .def("__repr__", [](const SimilarityFit& f) {
            return "SimilarityFit(" + repr(f.transform) + ", rms_residual=" + std::to_string(f.rms_residual) + ")";
        });

    const RobustFitOptions fd;
    m.def(
        "similarity_from_correspondences",
        [](const ArrayLike& source, const ArrayLike& target, const OptionalArrayLike& weights, double loss_scale,
           int iterations) {
            const FloatArray s = as_float_array(source, "source", {-1, 3}, "N, 3");
            const FloatArray t = as_float_array(target, "target", {s.shape(0), 3}, "N, 3");
            FloatArray w;
            if (!weights.is_none()) w = as_float_array(weights, "weights", {s.shape(0)}, "N");
            RobustFitOptions o;
            o.loss_scale = loss_scale;
            o.iterations = iterations;
            ReleaseGil release;
            return similarity_from_correspondences(s.data(), t.data(), std::size_t(s.shape(0)),
                                                   weights.is_none() ? nullptr : w.data(), o);
        },
        py::arg("source"), py::arg("target"), py::arg("weights") = py::none(), py::arg("loss_scale") = fd.loss_scale,
        py::arg("iterations") = fd.iterations, R"doc(
The similarity that maps `source` onto `target`: a robust, weighted Umeyama fit.

Minimises sum_i w_i rho(r_i), r_i = norm(target_i - T(source_i)), with the Cauchy loss
rho(r) = k^2 / 2 log(1 + (r / k)^2), k = loss_scale * the target's RMS spread, by iteratively
reweighted least squares (Umeyama's closed form each iteration, in float64).

Parameters
----------
source, target : array_like, shape (N, 3)
weights : array_like, shape (N,), optional
    >= 0 (confidences); None: all 1.
loss_scale : float
    k as a fraction of the scene size, >= 0; 0 is the plain least-squares fit.
iterations : int
    IRLS iterations at most, >= 1.

Returns
-------
SimilarityFit

Raises
------
ValueError
    For N < 3, non-finite points, negative weights (naming the index), all weights 0, or
    degenerate geometry (collinear or coincident points).)doc");

    py::class_<PredictionChunk>(m, "PredictionChunk", R"doc(
One window of a long capture: S views of H x W pixels in the window's own frame and scale.

Parameters
----------
points : array_like, shape (S, H, W, 3)
    Positions in the chunk's frame.
frame_ids : array_like of int, shape (S,)
    The global frame of each view (distinct).
valid : array_like of bool, shape (S, H, W), optional
    None: every pixel is predicted.
confidence : array_like, shape (S, H, W), optional
    None: every pixel weighs 1.
gaussians : GaussianCloud, optional
    The chunk's Gaussians to stitch, in its frame; None: alignment only.
name : str
    Names the chunk in error messages.
confidence_mapping : {"logit", "probability", "positive"}
    How a confidence becomes a weight (its probability).

Raises
------
ValueError
    Naming the chunk and the field for inconsistent shapes, repeated frame ids, a non-finite
    point at a valid pixel, or no valid pixel.)doc")
        .def(py::init([](const ArrayLike& points, const ArrayLike& frame_ids, const OptionalArrayLike& valid,
                         const OptionalArrayLike& confidence, std::optional<GaussianCloud> gaussians,
                         const std::string& name, const std::string& mapping) {
                 const FloatArray p = as_float_array(points, "points", {-1, -1, -1, 3}, "S, H, W, 3");
                 PredictionChunk c;
                 c.name = name;
                 c.views = int(p.shape(0));
                 c.height = int(p.shape(1));
                 c.width = int(p.shape(2));
                 c.points.assign(p.data(), p.data() + p.size());
                 const auto ids = as_array<std::int64_t>(frame_ids, "frame_ids", {p.shape(0)}, "S", "integer");
                 c.frame_ids.assign(ids.data(), ids.data() + ids.size());
                 if (!valid.is_none()) {
                     const auto v = as_array<std::uint8_t>(valid, "valid", {p.shape(0), p.shape(1), p.shape(2)},
                                                           "S, H, W", "bool");
                     c.valid.assign(v.data(), v.data() + v.size());
                 }
                 if (!confidence.is_none()) {
                     const FloatArray f = as_float_array(confidence, "confidence", {p.shape(0), p.shape(1), p.shape(2)},
                                                         "S, H, W");
                     c.confidence.assign(f.data(), f.data() + f.size());
                 }
                 c.confidence_mapping = parse_confidence_mapping(mapping, "confidence_mapping");
                 if (gaussians) c.gaussians = std::move(*gaussians);
                 c.validate();
                 return c;
             }),
             py::arg("points"), py::arg("frame_ids"), py::arg("valid") = py::none(), py::arg("confidence") = py::none(),
             py::arg("gaussians") = py::none(), py::arg("name") = "", py::arg("confidence_mapping") = "logit")
        .def_readonly("name", &PredictionChunk::name)
        .def_readonly("views", &PredictionChunk::views)
        .def_readonly("height", &PredictionChunk::height)
        .def_readonly("width", &PredictionChunk::width)
        .def_property_readonly("frame_ids", [](const PredictionChunk& c) {
            return copy_out(c.frame_ids, {py::ssize_t(c.frame_ids.size())});
        })
        .def_property_readonly("points", [](py::object self) {
            auto& c = self.cast<PredictionChunk&>();
            return view(c.points.data(), {c.views, c.height, c.width, 3}, self);
        })
        .def_readonly("gaussians", &PredictionChunk::gaussians)
        .def("__repr__", [](const PredictionChunk& c) {
            return "PredictionChunk(name='" + c.name + "', views=" + std::to_string(c.views) + ", " +
                   std::to_string(c.height) + " x " + std::to_string(c.width) + ", frames " +
                   std::to_string(c.frame_ids.front()) + ".." + std::to_string(c.frame_ids.back()) + ", " +
                   std::to_string(c.gaussians.size()) + " Gaussians)";
        });

    m.def(
        "read_prediction_chunk",
        [](const PathLike& path, const std::string& mapping) {
            const std::string p = fs_path(path);
            const ConfidenceMapping cm = parse_confidence_mapping(mapping, "confidence_mapping");
            ReleaseGil release;
            return read_prediction_chunk(p, cm);
        },
        py::arg("path"), py::arg("confidence_mapping") = "logit", R"doc(
Read a prediction .npz as a PredictionChunk.

The layout of ``read_prediction_npz`` with point maps ``points`` (S, H, W, 3) and an integer
array ``frame_ids`` (S,); ``valid`` and ``confidence`` are read when present; the Gaussians are
``read_prediction_npz``'s.

Parameters
----------
path : str or os.PathLike
confidence_mapping : {"logit", "probability", "positive"}

Returns
-------
PredictionChunk

Raises
------
FileError
    Naming the file and the array.)doc");

    py::class_<PairAlignment>(m, "PairAlignment", R"doc(
The estimate of one pair of chunks that share frames (``ChunkAlignment.pairs``).

Attributes
----------
a, b : int
    The chunks, a < b.
a_from_b : Similarity
    The robust fit x_a = T(x_b).
correspondences : int
    Shared valid pixels.
rms_residual : float
    Of the pairwise fit, in chunk a's units.
scene_size : float
    Spread of the shared points in chunk a's units.
aligned_rms : float
    RMS distance of the shared pixels' points after the final alignment, in chunk 0's units.)doc")
        .def_readonly("a", &PairAlignment::a)
        .def_readonly("b", &PairAlignment::b)
        .def_readonly("a_from_b", &PairAlignment::a_from_b)
        .def_readonly("correspondences", &PairAlignment::correspondences)
        .def_readonly("rms_residual", &PairAlignment::rms_residual)
        .def_readonly("scene_size", &PairAlignment::scene_size)
        .def_readonly("aligned_rms", &PairAlignment::aligned_rms)
        .def("__repr__", [](const PairAlignment& p) {
            return "PairAlignment(a=" + std::to_string(p.a) + ", b=" + std::to_string(p.b) +
                   ", correspondences=" + std::to_string(p.correspondences) + ", aligned_rms=" +
                   std::to_string(p.aligned_rms) + ")";
        });

    py::class_<ChunkAlignment>(m, "ChunkAlignment", R"doc(
The chunks' transforms into chunk 0's frame (``align_chunks``).

Attributes
----------
transforms : list of Similarity
    Chunk 0's frame from chunk i's; transforms[0] is the identity.
pairs : list of PairAlignment
    Every pair with an estimate.
residuals : list of float
    Per chunk, the RMS of its pairs' aligned_rms (chunk 0's units).
initial_cost, final_cost : float
    The pose graph's cost at the chained start and after optimisation.)doc")
        .def_readonly("transforms", &ChunkAlignment::transforms)
        .def_readonly("pairs", &ChunkAlignment::pairs)
        .def_readonly("residuals", &ChunkAlignment::residuals)
        .def_readonly("initial_cost", &ChunkAlignment::initial_cost)
        .def_readonly("final_cost", &ChunkAlignment::final_cost)
        .def("__repr__", [](const ChunkAlignment& a) {
            return "ChunkAlignment(" + std::to_string(a.transforms.size()) + " chunks, " +
                   std::to_string(a.pairs.size()) + " pairs)";
        });

    const AlignmentOptions ad;
    m.def(
        "align_chunks",
        [](const std::vector<PredictionChunk>& chunks, bool pose_graph, double loss_scale, int iterations,
           int min_correspondences) {
            const AlignmentOptions o = alignment_options(pose_graph, loss_scale, iterations, min_correspondences);
            ReleaseGil release;
            return align_chunks(chunks, o);
        },
        py::arg("chunks"), py::arg("pose_graph") = ad.pose_graph, py::arg("loss_scale") = ad.fit.loss_scale,
        py::arg("iterations") = ad.fit.iterations, py::arg("min_correspondences") = ad.min_correspondences, R"doc(
Align the chunks of a long capture into chunk 0's frame from the frames they share.

The same pixel of the same frame, valid in two chunks, is a correspondence between their point
maps, weighted by the product of the two confidences' probabilities. Every pair with at least
`min_correspondences` of them gets a robust similarity (``similarity_from_correspondences``);
then all chunks are solved together as a pose graph over similarities (chunk 0 fixed;
Levenberg-Marquardt), or, with ``pose_graph=False``, chained along the breadth-first tree from
chunk 0. Deterministic for any thread count.

Parameters
----------
chunks : list of PredictionChunk
pose_graph : bool
loss_scale : float
    The Cauchy constant as a fraction of the shared points' spread (0: plain least squares).
iterations : int
    IRLS iterations per pair at most.
min_correspondences : int
    >= 3.

Returns
-------
ChunkAlignment

Raises
------
ValueError
    Naming the chunk: no valid pixel, no shared frames with the chunks connected to chunk 0,
    degenerate shared geometry.)doc");

    py::class_<StitchResult>(m, "StitchResult", R"doc(
A stitched scene (``stitch``).

Attributes
----------
cloud : GaussianCloud
    In chunk 0's frame.
alignment : ChunkAlignment
    The transforms and residuals.
input_gaussians : int
    Gaussians of all chunks before fusion.)doc")
        .def_readonly("cloud", &StitchResult::cloud)
        .def_readonly("alignment", &StitchResult::alignment)
        .def_readonly("input_gaussians", &StitchResult::input_gaussians)
        .def("__repr__", [](const StitchResult& r) {
            return "StitchResult(" + std::to_string(r.cloud.size()) + " Gaussians from " +
                   std::to_string(r.input_gaussians) + ", " + std::to_string(r.alignment.transforms.size()) +
                   " chunks)";
        });

    m.def(
        "stitch",
        [](const std::vector<PredictionChunk>& chunks, double voxel_size, const Word& policy, bool pose_graph,
           double loss_scale, int min_correspondences, bool fuse, std::optional<std::size_t> memory_limit,
           const OptionalPathLike& work_dir, const py::kwargs& knobs) {
            const FusionParams params = parse_fusion_params("stitch", policy, knobs, true);
            StitchOptions o;
            o.alignment = alignment_options(pose_graph, loss_scale, RobustFitOptions{}.iterations, min_correspondences);
            o.fuse = fuse;
            o.memory_limit = memory_limit.value_or(0);
            if (!work_dir.is_none()) o.work_dir = fs_path(work_dir);
            ReleaseGil release;
            return stitch(chunks, voxel_size, params, o);
        },
        py::arg("chunks"), py::arg("voxel_size"), py::arg("policy") = "occupancy", py::kw_only(),
        py::arg("pose_graph") = ad.pose_graph, py::arg("loss_scale") = ad.fit.loss_scale,
        py::arg("min_correspondences") = ad.min_correspondences, py::arg("fuse") = true,
        py::arg("memory_limit") = py::none(), py::arg("work_dir") = py::none(), R"doc(
Stitch chunked predictions into one scene: align, transform, fuse.

``align_chunks``, then every chunk's Gaussians moved into chunk 0's frame (``transform``: SH
rotated exactly, scales multiplied) and fused with the voxel operator (``fuse_gaussians``), so
that overlapping surfaces become one layer.

Parameters
----------
chunks : list of PredictionChunk
    With their Gaussians.
voxel_size : float
    In chunk 0's units.
policy : str
    The fusion policy (``fuse_gaussians``); further fusion knobs as keyword arguments.
pose_graph, loss_scale, min_correspondences
    As ``align_chunks``.
fuse : bool
    False: concatenate the moved chunks (a baseline).
memory_limit : int, optional
    Bytes: fuse through a FusionStream that spills to `work_dir` (None: in memory).
work_dir : str or os.PathLike, optional

Returns
-------
StitchResult

Raises
------
ValueError
    As ``align_chunks``, for a chunk without Gaussians (naming it), and for fusion's errors.)doc");

    m.def(
        "fuse_chunks",
        [](const std::vector<PredictionChunk>& chunks, const std::vector<Similarity>& transforms, double voxel_size,
           const Word& policy, bool fuse, const py::kwargs& knobs) {
            const FusionParams params = parse_fusion_params("fuse_chunks", policy, knobs, true);
            StitchOptions o;
            o.fuse = fuse;
            ReleaseGil release;
            return fuse_chunks(chunks, transforms, voxel_size, params, o);
        },
        py::arg("chunks"), py::arg("transforms"), py::arg("voxel_size"), py::arg("policy") = "occupancy",
        py::kw_only(), py::arg("fuse") = true, R"doc(
Move every chunk's Gaussians by its transform and fuse them (``stitch`` with given transforms).

Parameters
----------
chunks : list of PredictionChunk
transforms : list of Similarity
    One per chunk, into the common frame.
voxel_size : float
policy : str
    As ``fuse_gaussians``; knobs as keyword arguments.
fuse : bool
    False: concatenate.

Returns
-------
GaussianCloud)doc");

    // The simulator's chunked captures.
    py::class_<CaptureChunk>(m, "CaptureChunk", R"doc(
One window of a simulated chunked capture (``simulate_chunked_capture``).

Attributes
----------
predictions : Predictions
    The window's views, in the window's frame (no head features).
frame_ids : (S,) int64 ndarray
world_from_chunk : Similarity
    The true transform into the world frame.)doc")
        .def_readonly("predictions", &CaptureChunk::predictions)
        .def_property_readonly("frame_ids", [](const CaptureChunk& c) {
            return copy_out(c.frame_ids, {py::ssize_t(c.frame_ids.size())});
        })
        .def_readonly("world_from_chunk", &CaptureChunk::world_from_chunk)
        .def(
            "prediction_chunk",
            [](const CaptureChunk& c, const std::string& name) {
                ReleaseGil release;
                return c.prediction_chunk(name);
            },
            py::arg("name") = "", "The window as stitching takes it (points, valid, confidence, frame ids, "
                                  "predictions.gaussians()).")
        .def("__repr__", [](const CaptureChunk& c) {
            return "CaptureChunk(frames " + std::to_string(c.frame_ids.front()) + ".." +
                   std::to_string(c.frame_ids.back()) + ", " + repr(c.world_from_chunk) + ")";
        });
    py::class_<ChunkedCapture>(m, "ChunkedCapture", R"doc(
A simulated chunked capture: the whole trajectory in one pass, and its windows.

Attributes
----------
trajectory : Predictions
    All frames, in the world frame.
chunks : list of CaptureChunk)doc")
        .def_readonly("trajectory", &ChunkedCapture::trajectory)
        .def_readonly("chunks", &ChunkedCapture::chunks)
        .def("__repr__", [](const ChunkedCapture& c) {
            return "ChunkedCapture(" + std::to_string(c.trajectory.views) + " frames, " +
                   std::to_string(c.chunks.size()) + " chunks)";
        });
    const ChunkedCaptureOptions kd;
    m.def(
        "simulate_chunked_capture",
        [](int frames, int window, int overlap, int width, int height, double pose_noise_rot_deg,
           double pose_noise_trans, double depth_noise, int target_views, int supersample, double min_scale,
           double max_scale, std::uint64_t seed) {
            SimulatorOptions o;
            o.views = frames;
            o.width = width;
            o.height = height;
            o.pose_noise_rot_deg = pose_noise_rot_deg;
            o.pose_noise_trans = pose_noise_trans;
            o.depth_noise = depth_noise;
            o.target_views = target_views;
            o.supersample = supersample;
            o.seed = seed;
            ChunkedCaptureOptions k;
            k.window = window;
            k.overlap = overlap;
            k.min_scale = min_scale;
            k.max_scale = max_scale;
            k.seed = seed;
            ReleaseGil release;
            return simulate_chunked_capture(o, k);
        },
        py::arg("frames") = 256, py::arg("window") = kd.window, py::arg("overlap") = kd.overlap,
        py::arg("width") = 64, py::arg("height") = 48, py::arg("pose_noise_rot_deg") = SimulatorOptions{}.pose_noise_rot_deg,
        py::arg("pose_noise_trans") = SimulatorOptions{}.pose_noise_trans,
        py::arg("depth_noise") = SimulatorOptions{}.depth_noise, py::arg("target_views") = 8,
        py::arg("supersample") = 1, py::arg("min_scale") = kd.min_scale, py::arg("max_scale") = kd.max_scale,
        py::arg("seed") = 0, R"doc(
Simulate a long capture predicted window by window.

The simulator's arc with `frames` frames, split into windows of `window` frames that overlap by
`overlap` (the last window ends at the last frame). Each window re-predicts its frames with its
own pose and depth errors (rms `pose_noise_rot_deg`, `pose_noise_trans`, `depth_noise`) and is
expressed in its own frame: its first true camera's coordinates times a scale drawn
log-uniformly from [min_scale, max_scale]. Bit-identical for a seed and any thread count.

Returns
-------
ChunkedCapture

Raises
------
ValueError
    Naming the option out of range.)doc");
}

}  // namespace avsplat::python
