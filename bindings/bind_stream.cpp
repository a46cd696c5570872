// Python binding of FusionStream: streaming (out-of-core) fuse_voxels / fuse_gaussians.
#include "fusion_params.h"
#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "progress_arg.h"
#include "release_gil.h"
#include "paths.h"

#include "avsplat/fusion/fusion_stream.h"

#include <limits>
#include <memory>
#include <sstream>
#include <string>

namespace avsplat::python {

namespace {

GaussianFusionResult finish_gaussians(FusionStream& s, const OptionalCallable& sink, const OptionalCallable& progress) {
    GaussianFusionResult r;
    {
        const PythonProgress reporting(progress);
        ReleaseGil release;
        if (sink.is_none()) {
            r = s.finish_gaussians();
        } else {
            r = s.finish_gaussians([&](GaussianFusionResult&& block) {
                py::gil_scoped_acquire gil;
                sink(py::cast(std::move(block)));
            });
        }
    }
    return r;
}

}  // namespace

void bind_stream(py::module_& m) {
    py::class_<FusionStream>(m, "FusionStream", R"doc(
Streaming fusion: ``fuse_voxels`` / ``fuse_gaussians`` on input fed chunk by chunk, in bounded
memory.

``FusionStream(voxel_size, policy='occupancy', memory_limit=None, work_dir=None, **knobs)``.
Chunks come in any order (e.g. one view at a time) through ``add(positions, features,
confidence=None)`` or ``add_gaussians(cloud)``, not both. ``finish()`` returns exactly (bit for
bit, diagnostics and sample_voxel included) what ``fuse_voxels`` / ``fuse_gaussians`` returns
on the concatenation of the chunks in the order they were added; sample indices are global.

Parameters
----------
voxel_size : float
    > 0.
policy : {"occupancy", "softmax", "mean"}
    As ``fuse_voxels`` / ``fuse_gaussians``; so are the other keyword knobs (``shape`` applies
    to Gaussians).
memory_limit : int, optional
    Bytes for the buffered input and for each block's fusion (None: 1 GiB). Input beyond a
    quarter of it is partitioned by blocks of voxel keys (ranges of (kx, ky, kz) in
    lexicographic order, chosen from the key quantiles) into spill files.
work_dir : str or os.PathLike, optional
    Folder for the spill files (None: the system's temporary folder); the stream uses a fresh
    subfolder that it removes when ``finish()`` returns or raises.

Notes
-----
Invalid samples are checked by the operator's own checks as each chunk is added: with
``on_invalid='raise'`` the ``add()`` of the first chunk holding one raises the operator's
ValueError for that chunk, naming the global index; with ``'drop'`` they are dropped there and
counted. ``finish(sink=callable)`` hands each block's fused voxels to ``sink(result)`` in key
order and keeps none of them (bounded memory; write them with GaussianPlyWriter);
``set_progress(callable)`` is called with (samples fused, samples added) during ``finish``.)doc")
        .def(py::init([](double voxel_size, const Word& policy, const OptionalInt& memory_limit,
                         const OptionalPathLike& work_dir, const py::kwargs& knobs) {
                 const FusionParams p = parse_fusion_params("FusionStream", policy, knobs, true);
                 std::size_t limit = 0;
                 if (!memory_limit.is_none()) {
                     if (py::isinstance<py::bool_>(memory_limit) || !py::isinstance<py::int_>(memory_limit))
                         throw py::type_error("memory_limit: expected an int (bytes) or None, got " +
                                              py::repr(memory_limit).cast<std::string>());
                     const py::int_ v(memory_limit);
                     if (v <= py::int_(0)) throw py::value_error("memory_limit: expected bytes > 0 or None");
                     if (v > py::int_(std::numeric_limits<std::size_t>::max()))
                         throw py::value_error("memory_limit: " + py::repr(memory_limit).cast<std::string>() +
                                               " bytes is more than this machine can address (2^64 - 1)");
                     limit = v.cast<std::size_t>();
                 }
                 const std::string dir = work_dir.is_none() ? std::string() : fs_path(work_dir);
                 return std::make_unique<FusionStream>(voxel_size, p, limit, dir);
             }),
             py::arg("voxel_size"), py::arg("policy") = "occupancy", py::arg("memory_limit") = py::none(),
             py::arg("work_dir") = py::none())
        .def(
            "add",
            [](FusionStream& s, const ArrayLike& positions, const ArrayLike& features, const OptionalArrayLike& confidence) {
                const FloatArray pos = as_float_array(positions, "positions", {-1, 3}, "N, 3");
                const py::ssize_t n = pos.shape(0);
                const std::string rows = std::to_string(n);
                const FloatArray feat = as_float_array(features, "features", {n, -1}, (rows + ", C").c_str());
                FloatArray conf;
                if (!confidence.is_none()) conf = as_float_array(confidence, "confidence", {n}, (rows + ",").c_str());
                const float* conf_ptr = confidence.is_none() ? nullptr : conf.data();
                ReleaseGil release;
                s.add(pos.data(), std::size_t(n), feat.data(), int(feat.shape(1)), conf_ptr);
            },
            py::arg("positions"), py::arg("features"), py::arg("confidence") = py::none(),
            "Adds a chunk: positions (N, 3), features (N, C), confidence (N,) or None, float32 (other dtypes "
            "are converted). Every chunk has the same C and all or none a confidence.")
        .def(
            "add_gaussians",
            [](FusionStream& s, const GaussianCloud& cloud) {
                ReleaseGil release(cloud);
                s.add_gaussians(cloud);
            },
            py::arg("cloud"),
            "Adds a GaussianCloud chunk; every chunk has the same SH degree, confidence presence and extras.")
        .def(
            "finish",
            [](FusionStream& s, const OptionalCallable& sink, const OptionalCallable& progress) -> FusionResult {
                if (s.takes_gaussians()) return py::cast(finish_gaussians(s, sink, progress));
                const PythonProgress reporting(progress);
                if (!sink.is_none()) {
                    FeatureFusionResult r;
                    {
                        ReleaseGil release;
                        r = s.finish([&](FeatureFusionResult&& block) {
                            py::gil_scoped_acquire gil;
                            sink(py::cast(std::move(block)));
                        });
                    }
                    return py::cast(std::move(r));
                }
                FeatureFusionResult r;
                {
                    ReleaseGil release;
                    r = s.finish();
                }
                return py::cast(std::move(r));
            },
            py::arg("sink") = py::none(), py::kw_only(), py::arg("progress") = py::none(),
            "Fuses block by block and returns a FeatureFusionResult (after add) or a GaussianFusionResult "
            "(after add_gaussians), identical to the in-memory operator's. With sink, calls sink(result) "
            "for each block's fused voxels in key order (their concatenation is that result) and returns "
            "only sample_voxel and dropped. The stream is spent afterwards. progress(done, total), when "
            "given, is called from the calling thread with the samples fused so far and the samples added: "
            "first (0 or the samples dropped while adding, total), after each block, last (total, total); "
            "an exception it raises stops finish and is raised from it.")
        .def("finish_gaussians", &finish_gaussians, py::arg("sink") = py::none(), py::kw_only(),
             py::arg("progress") = py::none(),
             "As finish() for a stream of Gaussians (also when no chunk was added).")
        .def(
            "set_progress",
            [](FusionStream& s, const OptionalCallable& progress) {
                if (progress.is_none()) {
                    s.set_progress({});
                    return;
                }
                s.set_progress([progress](std::size_t done, std::size_t total) {
                    py::gil_scoped_acquire gil;
                    progress(done, total);
                });
            },
            py::arg("progress"),
            "progress(done, total) is called during finish with the samples fused so far and the samples "
            "added, before the first block and after each; None removes it. An exception it raises stops "
            "finish and is raised from it.")
        .def_property_readonly("num_samples", &FusionStream::num_samples, "samples added so far")
        .def_property_readonly("num_blocks", &FusionStream::num_blocks, "spill files made so far, including blocks split again by finish() (0: all in memory)")
        .def_property_readonly("spilled_bytes", &FusionStream::spilled_bytes, "bytes written to spill files so far")
        .def_property_readonly("work_folder", &FusionStream::work_folder, "the spill folder ('' until the first spill)")
        .def("__repr__", [](const FusionStream& s) {
            std::ostringstream os;
            os << "FusionStream(samples=" << s.num_samples() << ", blocks=" << s.num_blocks()
               << ", spilled_bytes=" << s.spilled_bytes() << ")";
            return os.str();
        });
}

}  // namespace avsplat::python
