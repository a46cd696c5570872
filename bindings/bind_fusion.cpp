// Python bindings of SparseVoxelGrid, fuse_voxels and fuse_gaussians.
//
// Inputs that are C-contiguous float32 are used in place (no copy); results own their C++
// vectors and hand out numpy views of them, kept alive by the result object (no copy out).
// The heavy calls release the GIL. Knob keyword names are the C++ FusionParams field names.
#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "progress_arg.h"
#include "release_gil.h"
#include "fusion_params.h"

#include "avsplat/core/names.h"
#include "avsplat/fusion/names.h"
#include "avsplat/fusion/feature_decoder.h"
#include "avsplat/fusion/fusion.h"
#include "avsplat/fusion/fusion_knobs.h"
#include "avsplat/fusion/voxel_grid.h"

#include <pybind11/stl.h>

#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace avsplat::python {

namespace {

// The word `value` names, from the library's names table (core/names.h): TypeError for a
// non-string, ValueError (std::invalid_argument) naming the knob and the valid words otherwise.
template <class E>
E parse_choice(const py::handle& value, const char* knob) {
    if (!py::isinstance<py::str>(value))
        throw py::type_error(std::string(knob) + ": expected a string, one of " + enum_words<E>());
    return parse_enum<E>(value.cast<std::string>(), knob);
}

double parse_number(const py::handle& value, const char* knob) {
    if (py::isinstance<py::bool_>(value) || !(py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value) ||
                                              py::hasattr(value, "__float__")))
        throw py::type_error(std::string(knob) + ": expected a number, got " +
                             py::str(py::type::handle_of(value).attr("__name__")).cast<std::string>());
    return py::reinterpret_borrow<py::object>(value).cast<double>();
}

// FusionParams from the policy name and the keyword knobs of `function`, by the knob table
// (fusion_knobs.h). Unknown knobs raise TypeError naming them; `gaussian` says whether the
// Gaussian-only knobs (shape) apply.
FusionParams parse_params(const std::string& function, const py::handle& policy, const py::kwargs& knobs,
                          bool gaussian) {
    FusionParams p;
    p.policy = parse_choice<FusionPolicy>(policy, "policy");
    std::vector<std::string> unknown;
    for (const auto& item : knobs) {
        const std::string key = py::str(item.first).cast<std::string>();
        const py::handle value = item.second;
        const FusionKnob* knob = nullptr;
        for (const FusionKnob& k : fusion_knobs())
            if (k.name == key && k.name != "policy") knob = &k;
        if (knob == nullptr) {
            unknown.push_back(key);
            continue;
        }
        if (knob->gaussian_only && !gaussian)
            throw py::type_error(function + "(): '" + key + "' applies to fuse_gaussians only");
        if (knob->kind == FusionKnob::Kind::Number) {
            p.*knob->number = knob->none_is_zero && value.is_none() ? 0.0 : parse_number(value, key.c_str());
        } else {
            if (!py::isinstance<py::str>(value))
                throw py::type_error(key + ": expected a string, " + knob->range);
            knob->set(p, value.cast<std::string>());
        }
    }
    if (!unknown.empty()) {
        std::string names;
        for (const auto& u : unknown) names += (names.empty() ? "'" : ", '") + u + "'";
        std::string valid;
        for (const FusionKnob& k : fusion_knobs())
            if (k.name != "policy" && (gaussian || !k.gaussian_only)) valid += (valid.empty() ? "" : ", ") + k.name;
        throw py::type_error(function + "() got unexpected keyword argument(s) " + names + "; the knobs are " + valid);
    }
    validate(p);
    return p;
}

// A read-only numpy view of const storage owned by `owner`.
template <class T>
py::array_t<T> readonly_view(const T* data, std::vector<py::ssize_t> shape, const py::object& owner) {
    py::array_t<T> a = view(const_cast<T*>(data), std::move(shape), owner);
    a.attr("setflags")(py::arg("write") = false);
    return a;
}

template <class T>
py::array_t<T> vec_view(std::vector<T>& v, std::vector<py::ssize_t> shape, const py::object& owner) {
    return view(v.data(), std::move(shape), owner);
}

// The diagnostics and bookkeeping shared by both result types, as numpy views.
template <class Result>
void def_common(py::class_<Result>& cls) {
    cls.def_property_readonly(
           "voxel_coords",
           [](py::object self) {
               auto& r = self.cast<Result&>();
               return vec_view(r.voxel_coords, {py::ssize_t(r.size()), 3}, self);
           },
           "(M, 3) int32 voxel keys round(p / voxel_size), lexicographically increasing")
        .def_property_readonly(
            "sample_voxel",
            [](py::object self) {
                auto& r = self.cast<Result&>();
                return vec_view(r.sample_voxel, {py::ssize_t(r.sample_voxel.size())}, self);
            },
            "(N,) int32 voxel of each input sample, -1 for a dropped one")
        .def_property_readonly("dropped", [](const Result& r) { return r.dropped; },
                               "number of invalid samples dropped (on_invalid='drop')")
        .def("__len__", &Result::size);
    const std::pair<const char*, const char*> f32[] = {
        {"temperature", "(M,) float32 temperature: tau_v (occupancy), 1 (softmax), inf (mean)"},
        {"variance", "(M,) float32 E|p - mu_v|^2 of the voxel's positions"},
        {"reliability", "(M,) float32 r_v in [0, 1]"},
        {"entropy", "(M,) float32 -sum w log w of the final weights (nats)"}};
    for (const auto& [name, doc] : f32) {
        const std::string key = name;
        cls.def_property_readonly(
            name,
            [key](py::object self) {
                auto& d = self.cast<Result&>().diagnostics;
                std::vector<float>& v = key == "temperature" ? d.temperature
                                        : key == "variance"  ? d.variance
                                        : key == "reliability" ? d.reliability
                                                               : d.entropy;
                return vec_view(v, {py::ssize_t(v.size())}, self);
            },
            doc);
    }
    cls.def_property_readonly(
           "occupancy",
           [](py::object self) {
               auto& d = self.cast<Result&>().diagnostics;
               return vec_view(d.occupancy, {py::ssize_t(d.occupancy.size())}, self);
           },
           "(M,) int32 samples per voxel")
        .def_property_readonly(
            "kept",
            [](py::object self) {
                auto& d = self.cast<Result&>().diagnostics;
                return vec_view(d.kept, {py::ssize_t(d.kept.size())}, self);
            },
            "(M,) int32 samples with a non-zero final weight");
}

// The knobs with their defaults, ranges and one line each, from the knob table, so that the
// docstring cannot drift from the library.
std::string knob_doc() {
    const FusionParams d;
    std::ostringstream os;
    os << "\nKeyword knobs (the C++ FusionParams fields; defaults from the AVSplat paper; unknown knobs\n"
       << "raise TypeError, bad values ValueError naming the knob):\n";
    for (const FusionKnob& k : fusion_knobs()) {
        if (k.name == "policy") continue;
        os << "  " << k.name << "=" << k.get(d) << ": " << k.doc << "; " << k.range
           << (k.none_is_zero ? " (None: 0)" : "") << (k.gaussian_only ? " (fuse_gaussians only)" : "") << "\n";
    }
    return os.str();
}

// avsplat.defaults["fusion"]: FusionParams{} as a dict of the keyword names.
py::dict fusion_defaults() {
    const FusionParams d;
    py::dict out;
    for (const FusionKnob& k : fusion_knobs()) {
        if (k.kind == FusionKnob::Kind::Number) out[k.name.c_str()] = d.*k.number;
        else out[k.name.c_str()] = k.get(d);
    }
    return out;
}

// avsplat.fusion_knobs(): the table itself, for the documentation and for tools.
py::list knob_table() {
    const FusionParams d;
    py::list out;
    for (const FusionKnob& k : fusion_knobs()) {
        py::dict row;
        row["name"] = k.name;
        row["kind"] = k.kind == FusionKnob::Kind::Number ? "number" : "choice";
        row["default"] = k.kind == FusionKnob::Kind::Number ? py::object(py::float_(d.*k.number))
                                                             : py::object(py::str(k.get(d)));
        row["range"] = k.range;
        row["doc"] = k.doc;
        row["words"] = k.words;
        row["flag"] = fusion_knob_flag(k);
        row["gaussian_only"] = k.gaussian_only;
        out.append(row);
    }
    return out;
}

}  // namespace

FusionParams parse_fusion_params(const std::string& function, const py::handle& policy, const py::kwargs& knobs,
                                 bool gaussian) {
    return parse_params(function, policy, knobs, gaussian);
}

void bind_fusion(py::module_& m) {
    if (!py::hasattr(m, "defaults")) m.attr("defaults") = py::dict();
    m.attr("defaults")["fusion"] = fusion_defaults();
    m.def("fusion_knobs", &knob_table, R"doc(
The knobs of fuse_voxels, fuse_gaussians and ``avsplat fuse`` as one table.

Returns
-------
list of dict
    One dict per knob, policy first: ``name`` (the keyword), ``kind`` ('number' or 'choice'),
    ``default``, ``range`` (the valid values in words), ``doc`` (one line), ``words`` (the
    choices), ``flag`` (the command-line flag) and ``gaussian_only``.
)doc");
    py::class_<SparseVoxelGrid>(m, "SparseVoxelGrid", R"doc(
The occupied voxels of a point set and its samples grouped by voxel (CSR).

``SparseVoxelGrid(positions, voxel_size, on_invalid='raise')``. Voxels are numbered in
lexicographic order of their keys; the samples of voxel v are
``sample_indices[voxel_offsets[v]:voxel_offsets[v + 1]]``, in increasing input index. The
result does not depend on the number of threads.

Parameters
----------
positions : array_like, shape (N, 3)
    float32 (other dtypes are converted once).
voxel_size : float
    > 0; the voxel of p is round(p / voxel_size) per axis, half away from zero.
on_invalid : {"raise", "drop"}
    For NaN/Inf positions: raise ValueError naming positions[i, axis], or drop them. A key
    outside int32 always raises.)doc")
        .def(py::init([](const ArrayLike& positions, double voxel_size, const Word& on_invalid) {
                 const FloatArray p = as_float_array(positions, "positions", {-1, 3}, "N, 3");
                 const InvalidPolicy policy = parse_choice<InvalidPolicy>(on_invalid, "on_invalid");
                 ReleaseGil release;
                 return SparseVoxelGrid(p.data(), std::size_t(p.shape(0)), voxel_size, policy);
             }),
             py::arg("positions"), py::arg("voxel_size"), py::arg("on_invalid") = to_string(FusionParams{}.on_invalid))
        .def_property_readonly("voxel_size", &SparseVoxelGrid::voxel_size)
        .def_property_readonly("num_samples", &SparseVoxelGrid::num_samples, "N, including dropped samples")
        .def_property_readonly("num_voxels", &SparseVoxelGrid::num_voxels, "M, occupied voxels")
        .def_property_readonly("dropped", &SparseVoxelGrid::dropped)
        .def_property_readonly("max_occupancy", [](const SparseVoxelGrid& g) { return g.max_occupancy(); })
        .def_property_readonly(
            "voxel_coords",
            [](py::object self) {
                auto& g = self.cast<SparseVoxelGrid&>();
                return readonly_view(g.voxel_coords().data(), {py::ssize_t(g.num_voxels()), 3}, self);
            },
            "(M, 3) int32 voxel keys (read-only view)")
        .def_property_readonly(
            "voxel_offsets",
            [](py::object self) {
                auto& g = self.cast<SparseVoxelGrid&>();
                return readonly_view(g.voxel_offsets().data(), {py::ssize_t(g.voxel_offsets().size())}, self);
            },
            "(M + 1,) int64 offsets into sample_indices (read-only view)")
        .def_property_readonly(
            "sample_indices",
            [](py::object self) {
                auto& g = self.cast<SparseVoxelGrid&>();
                return readonly_view(g.sample_indices().data(), {py::ssize_t(g.sample_indices().size())}, self);
            },
            "(N - dropped,) int32 input indices grouped by voxel (read-only view)")
        .def_property_readonly(
            "sample_voxel",
            [](py::object self) {
                auto& g = self.cast<SparseVoxelGrid&>();
                return readonly_view(g.sample_voxel().data(), {py::ssize_t(g.num_samples())}, self);
            },
            "(N,) int32 voxel of each sample, -1 for a dropped one (read-only view)")
        .def_property_readonly(
            "occupancy",
            [](const SparseVoxelGrid& g) {
                return move_out(g.occupancy(), {py::ssize_t(g.num_voxels())});
            },
            "(M,) int32 samples per voxel")
        .def("__len__", &SparseVoxelGrid::num_voxels)
        .def("__repr__", [](const SparseVoxelGrid& g) {
            std::ostringstream os;
            os << "SparseVoxelGrid(voxels=" << g.num_voxels() << ", samples=" << g.num_samples()
               << ", dropped=" << g.dropped() << ", voxel_size=" << g.voxel_size() << ")";
            return os.str();
        });

    py::class_<FeatureFusionResult> features(m, "FeatureFusionResult",
                                             "Result of fuse_voxels: M fused samples in voxel order. Arrays are "
                                             "numpy views of the result's storage.");
    features
        .def_property_readonly(
            "positions",
            [](py::object self) {
                auto& r = self.cast<FeatureFusionResult&>();
                return vec_view(r.positions, {py::ssize_t(r.size()), 3}, self);
            },
            "(M, 3) float32 weighted mean positions")
        .def_property_readonly(
            "features",
            [](py::object self) {
                auto& r = self.cast<FeatureFusionResult&>();
                return vec_view(r.features, {py::ssize_t(r.size()), py::ssize_t(r.channels)}, self);
            },
            "(M, C) float32 weighted mean features")
        .def_property_readonly("channels", [](const FeatureFusionResult& r) { return r.channels; });
    def_common(features);
    features.def("__repr__", [](const FeatureFusionResult& r) {
        std::ostringstream os;
        os << "FeatureFusionResult(voxels=" << r.size() << ", channels=" << r.channels << ", samples="
           << r.sample_voxel.size() << ", dropped=" << r.dropped << ")";
        return os.str();
    });

    py::class_<GaussianFusionResult> gaussians(m, "GaussianFusionResult",
                                               "Result of fuse_gaussians: the fused GaussianCloud (M Gaussians) "
                                               "and per-voxel diagnostics, as numpy views.");
    gaussians
        .def_property_readonly(
            "cloud", [](GaussianFusionResult& r) -> GaussianCloud& { return r.cloud; },
            py::return_value_policy::reference_internal, "the fused GaussianCloud (a view into the result)")
        .def_property_readonly(
            "positions",
            [](py::object self) {
                auto& r = self.cast<GaussianFusionResult&>();
                return vec_view(r.cloud.means, {py::ssize_t(r.size()), 3}, self);
            },
            "(M, 3) float32 fused means (= cloud.means)");
    def_common(gaussians);
    gaussians.def("__repr__", [](const GaussianFusionResult& r) {
        std::ostringstream os;
        os << "GaussianFusionResult(voxels=" << r.size() << ", sh_degree=" << r.cloud.sh_degree
           << ", samples=" << r.sample_voxel.size() << ", dropped=" << r.dropped << ")";
        return os.str();
    });

    m.def(
        "fuse_voxels",
        [](const ArrayLike& positions, const ArrayLike& features, double voxel_size, const OptionalArrayLike& confidence,
           const Word& policy, const OptionalCallable& progress, const py::kwargs& knobs) {
            const FusionParams p = parse_params("fuse_voxels", policy, knobs, false);
            const FloatArray pos = as_float_array(positions, "positions", {-1, 3}, "N, 3");
            const py::ssize_t n = pos.shape(0);
            const std::string rows = std::to_string(n);  // N from positions, in the messages
            const FloatArray feat = as_float_array(features, "features", {n, -1}, (rows + ", C").c_str());
            FloatArray conf;
            if (!confidence.is_none()) conf = as_float_array(confidence, "confidence", {n}, (rows + ",").c_str());
            const float* conf_ptr = confidence.is_none() ? nullptr : conf.data();
            const PythonProgress reporting(progress);
            ReleaseGil release;
            return fuse_voxels(pos.data(), std::size_t(n), feat.data(), int(feat.shape(1)), voxel_size, conf_ptr, p);
        },
        py::arg("positions"), py::arg("features"), py::arg("voxel_size"), py::arg("confidence") = py::none(),
        py::arg("policy") = to_string(FusionParams{}.policy), py::kw_only(), py::arg("progress") = py::none(),
        (std::string(R"doc(
Fuses N samples into one per occupied voxel (AnySplat / AVSplat raw-feature fusion).

  positions   (N, 3) float32
  features    (N, C) float32, any C >= 0
  voxel_size  float > 0
  confidence  (N,) float32 or None (then every policy gives the plain average)
  policy      'occupancy' (AVSplat Algorithm 2), 'softmax' (AnySplat: softmax of the raw
              confidence) or 'mean'

Returns a FeatureFusionResult with positions (M, 3), features (M, C), voxel_coords (M, 3),
sample_voxel (N,) and the diagnostics occupancy, temperature, variance, reliability, kept,
entropy (M,). C-contiguous float32 inputs are not copied; the GIL is released while fusing.
Invalid samples raise ValueError naming the field and first bad index, or are dropped and
counted with on_invalid='drop'.

  progress    callable(done, total) or None: samples fused of N, reported at the start and
              the end; see fuse_gaussians.)doc") + knob_doc()).c_str());

    m.def(
        "fuse_gaussians",
        [](const GaussianCloud& cloud, double voxel_size, const Word& policy, const OptionalCallable& progress,
           const py::kwargs& knobs) {
            const FusionParams p = parse_params("fuse_gaussians", policy, knobs, true);
            const PythonProgress reporting(progress);
            ReleaseGil release(cloud);
            return fuse_gaussians(cloud, voxel_size, p);
        },
        py::arg("cloud"), py::arg("voxel_size"), py::arg("policy") = to_string(FusionParams{}.policy), py::kw_only(),
        py::arg("progress") = py::none(),
        (std::string(R"doc(
Fuses a GaussianCloud into one Gaussian per occupied voxel of its means.

  cloud       GaussianCloud (N Gaussians); cloud.confidence, when present, drives the weights
  voxel_size  float > 0
  policy      'occupancy', 'softmax' or 'mean'
  shape       'average' (weighted log-scales and hemisphere-aligned quaternions) or 'moment'
              (moment matching of the covariances plus the spread of the means)

Means, SH, opacities, extras and confidence are weighted means. Returns a GaussianFusionResult
(cloud, positions, voxel_coords, sample_voxel and the per-voxel diagnostics). The GIL is
released while fusing.

  progress    callable(done, total) or None: called with the samples fused so far and N, from
              the calling thread, up to 64 times along the fusion: first (0, N), done never
              decreases, last (N, N); the GIL is taken only for the call. An exception it
              raises stops the fusion and is raised from here. The result does not depend on
              it.)doc") + knob_doc()).c_str());

    py::class_<FeatureLayout>(m, "FeatureLayout", R"doc(
Where each Gaussian field sits in a raw feature vector (``decode_gaussians``,
``encode_gaussians``).

The default is the packed layout [opacity | scale x3 | rotation x4 | SH], channels = 8 + 3 K.
``FeatureLayout(opacity=0, scale=1, rotation=4, sh=8, sh_degree=0)``.

Parameters
----------
opacity : int
    First channel of the opacity logit (1 channel).
scale : int
    First channel of the log scales (3).
rotation : int
    First channel of the quaternion w, x, y, z (4).
sh : int
    First channel of the SH coefficients (3 (sh_degree + 1)^2, laid out [K][3], degree 0
    first).
sh_degree : int
    0..3.)doc")
        .def(py::init([](int opacity, int scale, int rotation, int sh, int sh_degree) {
                 FeatureLayout l;
                 l.opacity = opacity;
                 l.scale = scale;
                 l.rotation = rotation;
                 l.sh = sh;
                 l.sh_degree = sh_degree;
                 l.validate();
                 return l;
             }),
             py::arg("opacity") = FeatureLayout{}.opacity, py::arg("scale") = FeatureLayout{}.scale,
             py::arg("rotation") = FeatureLayout{}.rotation, py::arg("sh") = FeatureLayout{}.sh,
             py::arg("sh_degree") = FeatureLayout{}.sh_degree)
        .def_readonly("opacity", &FeatureLayout::opacity)
        .def_readonly("scale", &FeatureLayout::scale)
        .def_readonly("rotation", &FeatureLayout::rotation)
        .def_readonly("sh", &FeatureLayout::sh)
        .def_readonly("sh_degree", &FeatureLayout::sh_degree)
        .def_property_readonly("channels", &FeatureLayout::channels,
                               "one past the last channel any field uses (the smallest C that fits)")
        .def("__repr__", [](const FeatureLayout& l) {
            std::ostringstream os;
            os << "FeatureLayout(opacity=" << l.opacity << ", scale=" << l.scale << ", rotation=" << l.rotation
               << ", sh=" << l.sh << ", sh_degree=" << l.sh_degree << ")";
            return os.str();
        });

    m.def(
        "decode_gaussians",
        [](const ArrayLike& positions, const ArrayLike& features, const FeatureLayout& layout,
           const OptionalArrayLike& confidence) {
            const FloatArray p = as_float_array(positions, "positions", {-1, 3}, "N, 3");
            const py::ssize_t n = p.shape(0);
            const FloatArray f = as_float_array(features, "features", {n, -1}, "N, C");
            FloatArray c;
            if (!confidence.is_none()) c = as_float_array(confidence, "confidence", {n}, "N");
            const int channels = static_cast<int>(f.shape(1));
            ReleaseGil release;
            return decode_gaussians(p.data(), std::size_t(n), f.data(), channels, layout,
                                    confidence.is_none() ? nullptr : c.data());
        },
        py::arg("positions"), py::arg("features"), py::arg("layout") = FeatureLayout{},
        py::arg("confidence") = py::none(), R"doc(
Decode raw Gaussian-head features into Gaussians with AnySplat's activations.

For fusing the way AnySplat and AVSplat do: ``fuse_voxels`` on the raw features, then decode.
opacity = sigmoid(logit), scale = exp(log scale), rotation = q / norm(q), SH as is; computed in
float64, rounded once.

Parameters
----------
positions : array_like, shape (N, 3), float32
    The means.
features : array_like, shape (N, C), float32
    Raw features, C >= layout.channels.
layout : FeatureLayout
    Where the fields sit (default: [opacity | log scale x3 | quat | SH0]).
confidence : array_like, shape (N,), float32, optional
    Copied into the cloud's confidence channel.

Returns
-------
GaussianCloud
    N Gaussians of SH degree ``layout.sh_degree``.

Raises
------
ValueError
    Naming the first bad sample: non-finite values (features[i, c]), a log scale above 88.72
    (whose exponential overflows float32), a zero quaternion.)doc");

    m.def(
        "encode_gaussians",
        [](const GaussianCloud& cloud, const FeatureLayout& layout) {
            std::vector<float> f;
            {
                ReleaseGil release(cloud);
                f = encode_gaussians(cloud, layout);
            }
            return move_out(std::move(f), {py::ssize_t(cloud.size()), py::ssize_t(layout.channels())});
        },
        py::arg("cloud"), py::arg("layout") = FeatureLayout{}, R"doc(
The inverse of ``decode_gaussians``: the raw features of a GaussianCloud.

The logit of the opacity clamped to [1e-6, 1 - 1e-6], the log of the scale floored at FLT_MIN,
the normalised quaternion, SH as is; unused channels 0.

Parameters
----------
cloud : GaussianCloud
    N Gaussians; its SH degree must equal ``layout.sh_degree``.
layout : FeatureLayout
    Where the fields go.

Returns
-------
ndarray, shape (N, layout.channels), float32

Raises
------
ValueError
    If the SH degrees differ.)doc");
}

}  // namespace avsplat::python
