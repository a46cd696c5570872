// Python bindings of the renderer (render.h), the image metrics (metrics.h) and, with Open3D,
// the PNG writers (io/image.h).
#include "module.h"
#include "typed_args.h"
#include "paths.h"
#include "numpy_arrays.h"
#include "release_gil.h"

#include "avsplat/core/names.h"
#include "avsplat/render/names.h"
#include "avsplat/metrics/metrics.h"
#include "avsplat/render/render.h"
#include "avsplat/render/render_cuda.h"
#include "avsplat/io/image.h"

#include <pybind11/stl.h>

#include <optional>

#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace avsplat::python {

namespace {

using IntArray = py::array_t<std::int32_t>;

/// A float32 image of shape (H, W) or (H, W, C); returns {H, W, C} (C = 1 for 2D).
std::vector<py::ssize_t> image_shape(const FloatArray& a, const char* arg) {
    if (a.ndim() == 2) return {a.shape(0), a.shape(1), 1};
    if (a.ndim() == 3) return {a.shape(0), a.shape(1), a.shape(2)};
    throw py::value_error(std::string(arg) + ": expected an image of shape (H, W) or (H, W, C)");
}

// The data range psnr assumes when none is given: 1 for floats, the integer dtype's range for
// integers (uint8 images are 0..255: read as [0, 1] they gave a meaningless, negative PSNR).
double psnr_range(const py::handle& a, const py::handle& b) {
    const auto np = py::module_::import("numpy");
    const py::dtype da = np.attr("asarray")(a).attr("dtype"), db = np.attr("asarray")(b).attr("dtype");
    const char ka = da.kind(), kb = db.kind();
    const auto integer = [](char k) { return k == 'u' || k == 'i' || k == 'b'; };
    if (!integer(ka) && !integer(kb)) return 1.0;
    const std::string names = "a is " + py::cast<std::string>(da.attr("name")) + ", b is " + py::cast<std::string>(db.attr("name"));
    if (!da.is(db) && !da.equal(db))
        throw py::value_error("psnr: " + names + ": give both in one dtype (uint8 images, or floats in [0, 1]), "
                              "or pass max_value");
    // scikit-image's data_range: the dtype's whole range (255 for uint8 and int8, 1 for bool).
    if (ka == 'b') return 1.0;
    const py::object info = np.attr("iinfo")(da);
    return py::cast<double>(info.attr("max")) - py::cast<double>(info.attr("min"));
}

FloatArray as_image(const py::handle& obj, const char* arg) {
    try {
        return as_contiguous<float>(obj, arg, "float");
    } catch (const py::value_error& e) {
        if (std::string(e.what()).find("real numbers") != std::string::npos) throw;
        throw py::value_error(std::string(arg) + ": expected a float array of shape (H, W) or (H, W, C)");
    }
}

}  // namespace

void bind_render(py::module_& m) {
    py::class_<RenderStats>(m, "RenderStats", "Counters and stage timings of one render.")
        .def_readonly("gaussians", &RenderStats::gaussians, "Gaussians in the cloud")
        .def_readonly("visible", &RenderStats::visible, "Gaussians that survived culling")
        .def_readonly("tile_instances", &RenderStats::tile_instances, "(splat, tile) pairs")
        .def_readonly("blends", &RenderStats::blends,
                      "Gaussian-pixel pairs evaluated (pixel in the splat's box, not saturated)")
        .def_readonly("contributions", &RenderStats::contributions, "sum of contributors")
        .def_readonly("threads", &RenderStats::threads, "OpenMP threads used")
        .def_readonly("seconds_projection", &RenderStats::seconds_projection,
                      "wall time of culling, projection and SH evaluation")
        .def_readonly("seconds_sorting", &RenderStats::seconds_sorting, "wall time of tile binning and sorting")
        .def_readonly("seconds_blending", &RenderStats::seconds_blending, "wall time of per-tile compositing")
        .def_readonly("seconds_total", &RenderStats::seconds_total, "wall time of the whole render() call")
        .def("summary", &RenderStats::summary,
             "One line, e.g. 'visible 1000/1200, 5000 tile instances, 1.2e6 blends, 3.1 ms'.")
        .def("__repr__", [](const RenderStats& s) { return "RenderStats(" + s.summary() + ")"; });

    py::class_<RenderResult>(m, "RenderResult", R"doc(
The images of one render.

Arrays are numpy views of the result's storage; H = camera.height, W = camera.width.

Attributes
----------
color : (H, W, 3) float32 ndarray
    Composited colour, background included.
alpha : (H, W) float32 ndarray
    Accumulated opacity 1 - T.
depth : (H, W) float32 ndarray
    Expected depth sum(w z) / alpha, 0 where alpha is 0.
contributors : (H, W) int32 ndarray
    Number of splats blended into each pixel.
contribution_max : (N,) float32 ndarray or None
    Per Gaussian, the max over pixels of alpha T (None unless
    ``render(..., gaussian_contributions=True)``).
contribution_sum : (N,) float32 ndarray or None
    Per Gaussian, the sum over pixels of alpha T (likewise).
stats : RenderStats
    Timings and counts of the stages.)doc")
        .def_readonly("width", &RenderResult::width, "W = camera.width")
        .def_readonly("height", &RenderResult::height, "H = camera.height")
        .def_property_readonly(
            "color",
            [](py::object self) {
                auto& r = self.cast<RenderResult&>();
                return view(r.color.data(), {r.height, r.width, 3}, self);
            },
            "(H, W, 3) float32")
        .def_property_readonly(
            "alpha",
            [](py::object self) {
                auto& r = self.cast<RenderResult&>();
                return view(r.alpha.data(), {r.height, r.width}, self);
            },
            "(H, W) float32")
        .def_property_readonly(
            "depth",
            [](py::object self) {
                auto& r = self.cast<RenderResult&>();
                return view(r.depth.data(), {r.height, r.width}, self);
            },
            "(H, W) float32, expected depth (0 where alpha is 0)")
        .def_property_readonly(
            "contributors",
            [](py::object self) {
                auto& r = self.cast<RenderResult&>();
                return view(r.contributors.data(), {r.height, r.width}, self);
            },
            "(H, W) int32")
        .def_property_readonly(
            "contribution_max",
            [](py::object self) -> py::object {
                auto& r = self.cast<RenderResult&>();
                if (!r.has_gaussian_contributions) return py::none();
                return view(r.contribution_max.data(), {py::ssize_t(r.contribution_max.size())}, self);
            },
            "(N,) float32: per Gaussian, the max over pixels of its alpha T (the weight it has in the "
            "composite, or would have at the splat that stops a pixel); None unless asked for")
        .def_property_readonly(
            "contribution_sum",
            [](py::object self) -> py::object {
                auto& r = self.cast<RenderResult&>();
                if (!r.has_gaussian_contributions) return py::none();
                return view(r.contribution_sum.data(), {py::ssize_t(r.contribution_sum.size())}, self);
            },
            "(N,) float32: per Gaussian, the sum over pixels of its alpha T; None unless asked for")
        .def_readonly("stats", &RenderResult::stats, "RenderStats of this render")
        .def("__repr__", [](const RenderResult& r) {
            std::ostringstream os;
            os << "RenderResult(" << r.width << "x" << r.height << ", " << r.stats.summary() << ")";
            return os.str();
        });

    py::class_<RenderWorkspace>(m, "RenderWorkspace", R"doc(
Memory that CPU renders reuse from one call to the next: ``render(..., workspace=ws)``.

It holds the per-Gaussian records and sort keys, the depth-sorted records and the tile lists,
about 170 bytes per Gaussian plus 4 per tile instance and an eighth of headroom. Without one,
every render allocates these afresh and the kernel clears each new page; rendering many views
of a cloud with one workspace skips that, with the same images bit for bit. The memory grows
to the largest frame rendered and is held until ``release()`` or the object is collected.

Notes
-----
One render at a time: a render given a workspace that another thread's render is using raises
RuntimeError. Ignored by ``backend="cuda"``.)doc")
        .def(py::init<>(), "An empty workspace (holds no memory until the first render).")
        .def_property_readonly("bytes", &RenderWorkspace::bytes, "int: bytes of memory held now")
        .def("release", &RenderWorkspace::release,
             "Frees the memory held; the workspace stays usable. RuntimeError while another thread's render\n"
             "uses it.")
        .def("__repr__", [](const RenderWorkspace& w) {
            return "RenderWorkspace(" + std::to_string(w.bytes()) + " bytes)";
        });

    const RenderOptions kRenderDefaults{};
    // avsplat.defaults["render"]: the keyword defaults of render(), for Python code that needs
    // the numbers (reports, notebooks) instead of restating them.
    if (!py::hasattr(m, "defaults")) m.attr("defaults") = py::dict();
    m.attr("defaults")["render"] = py::dict(
        py::arg("backend") = to_string(kRenderDefaults.backend), py::arg("precision") = to_string(kRenderDefaults.precision),
        py::arg("background") = py::make_tuple(kRenderDefaults.background[0], kRenderDefaults.background[1],
                                               kRenderDefaults.background[2]),
        py::arg("antialiased") = kRenderDefaults.antialiased, py::arg("low_pass") = kRenderDefaults.low_pass,
        py::arg("alpha_threshold") = kRenderDefaults.alpha_threshold,
        py::arg("transmittance_stop") = kRenderDefaults.transmittance_stop,
        py::arg("extent_sigma") = kRenderDefaults.extent_sigma,
        py::arg("gaussian_contributions") = kRenderDefaults.gaussian_contributions);

    m.def(
        "render",
        [](const GaussianCloud& cloud, const Camera& camera, const std::string& backend,
           const std::string& precision, const std::array<float, 3>& background, bool antialiased,
           float low_pass, float alpha_threshold, float transmittance_stop, float extent_sigma,
           bool gaussian_contributions, RenderWorkspace* workspace) {
            RenderOptions o;
            o.backend = parse_backend(backend);
            o.precision = parse_precision(precision);
            o.background = background;
            o.antialiased = antialiased;
            o.low_pass = low_pass;
            o.alpha_threshold = alpha_threshold;
            o.transmittance_stop = transmittance_stop;
            o.extent_sigma = extent_sigma;
            o.gaussian_contributions = gaussian_contributions;
            ReleaseGil release(cloud);
            return workspace ? render(cloud, camera, o, *workspace) : render(cloud, camera, o);
        },
        // Defaults are RenderOptions' (render.h), so the binding cannot drift from the library.
        py::arg("cloud"), py::arg("camera"), py::arg("backend") = to_string(kRenderDefaults.backend),
        py::arg("precision") = to_string(kRenderDefaults.precision),
        py::arg("background") = kRenderDefaults.background, py::arg("antialiased") = kRenderDefaults.antialiased,
        py::arg("low_pass") = kRenderDefaults.low_pass, py::arg("alpha_threshold") = kRenderDefaults.alpha_threshold,
        py::arg("transmittance_stop") = kRenderDefaults.transmittance_stop,
        py::arg("extent_sigma") = kRenderDefaults.extent_sigma,
        py::arg("gaussian_contributions") = kRenderDefaults.gaussian_contributions,
        py::arg("workspace") = py::none(),
        R"doc(
Render a GaussianCloud from a Camera with the 3DGS forward pass (gsplat's conventions).

Parameters
----------
cloud : GaussianCloud
    N Gaussians.
camera : Camera
    Pinhole camera; pixel (i, j) has its centre at (i + 0.5, j + 0.5).
backend : {"cpu", "cuda"}
    The renderer.
precision : {"float32", "float64"}
    The fast path or the reference path (CPU).
background : tuple of 3 float
    (r, g, b) behind the splats.
antialiased : bool
    Multiply opacities by the low-pass compensation (Mip-Splatting).
low_pass : float
    Pixels^2 added to the 2D covariance diagonal, >= 0.
alpha_threshold : float
    Splats below this alpha are skipped at a pixel, in (0, 1).
transmittance_stop : float
    A pixel stops when its transmittance would fall below this, in (0, 1).
extent_sigma : float
    k of the k-sigma box bounding a splat's footprint, > 0.
gaussian_contributions : bool
    Also compute, per Gaussian, the max and the sum over pixels of its alpha T
    (``contribution_max``, ``contribution_sum``, (N,) float32). CPU only.
workspace : RenderWorkspace, optional
    Memory the CPU renderer reuses between calls (same image; saves allocating and clearing
    its buffers when rendering many views).

Returns
-------
RenderResult
    ``color`` (H, W, 3), ``alpha``, ``depth`` and ``contributors`` (H, W), with H, W the
    camera's height and width.

Raises
------
ValueError
    For a bad cloud, camera or option (naming it).
DeviceError
    When the CUDA back end is not available (a RuntimeError).

Notes
-----
The GIL is released while rendering.)doc");

    m.def("cuda_device_count", &cuda_device_count, R"doc(
Number of CUDA devices that ``render(..., backend="cuda")`` can use.

Returns
-------
int
    0 when avsplat was built without the CUDA renderer, or when no driver or device is
    present; then ``backend="cuda"`` raises DeviceError. Never raises.)doc");

    m.def(
        "psnr",
        [](const ArrayLike& a, const ArrayLike& b, std::optional<double> max_value) {
            if (!max_value) max_value = psnr_range(a, b);
            const FloatArray x = as_image(a, "a");
            std::vector<py::ssize_t> shape(x.shape(), x.shape() + x.ndim());
            std::string dims;
            for (std::size_t k = 0; k < shape.size(); ++k) dims += (k ? ", " : "") + std::to_string(shape[k]);
            const FloatArray y = as_float_array(b, "b", shape, dims.c_str());
            const std::size_t n = std::size_t(x.size());
            ReleaseGil release;
            return psnr(x.data(), y.data(), n, *max_value);
        },
        py::arg("a"), py::arg("b"), py::arg("max_value") = py::none(),
        R"doc(
Peak signal-to-noise ratio in dB, 10 log10(max_value^2 / MSE) over all values.

Parameters
----------
a, b : array_like, same shape, e.g. (H, W, 3)
    Images: float in [0, 1], or both of one integer dtype (uint8 in [0, 255], ...).
max_value : float or None
    The data range. None: 1.0 for float arrays, the integer dtype's range for integer arrays
    (max - min: 255 for uint8 and int8; 1 for bool), as scikit-image's data_range.

Returns
-------
float
    The PSNR in dB; inf when the arrays are equal.

Raises
------
ValueError
    When the shapes differ, or with max_value None when a and b have different dtypes (uint8
    and float), whose ranges disagree.)doc");

    m.def(
        "ssim",
        [](const ArrayLike& a, const ArrayLike& b) {
            const FloatArray x = as_image(a, "a");
            const std::vector<py::ssize_t> s = image_shape(x, "a");
            const FloatArray y = x.ndim() == 2 ? as_float_array(b, "b", {s[0], s[1]}, "H, W")
                                               : as_float_array(b, "b", {s[0], s[1], s[2]}, "H, W, C");
            ReleaseGil release;
            return ssim(x.data(), y.data(), int(s[0]), int(s[1]), int(s[2]));
        },
        py::arg("a"), py::arg("b"),
        R"doc(
Structural similarity, as the 3DGS evaluation code computes it.

An 11 x 11 Gaussian window with sigma 1.5, zero padding, C1 = 0.01^2, C2 = 0.03^2; the mean
over pixels and channels.

Parameters
----------
a, b : array_like of float, shape (H, W, C) or (H, W)
    Images with values in [0, 1].

Returns
-------
float
    The SSIM, 1 for equal images.

Raises
------
ValueError
    If the shapes differ.)doc");

    m.def(
        "write_color_png",
        [](const PathLike& path, const ArrayLike& rgb) {
            const std::string p = fs_path(path);
            const FloatArray a = as_float_array(rgb, "rgb", {-1, -1, 3}, "H, W, 3");
            ReleaseGil release;
            write_color_png(p, a.data(), int(a.shape(1)), int(a.shape(0)));
        },
        py::arg("path"), py::arg("rgb"),
        "Writes an (H, W, 3) float RGB image as an 8-bit PNG: round(255 clamp(v, 0, 1)), NaN -> 0.\n"
        "The path must end in .png; OSError when the file cannot be written.");
    m.def(
        "write_alpha_png",
        [](const PathLike& path, const ArrayLike& alpha) {
            const std::string p = fs_path(path);
            const FloatArray a = as_float_array(alpha, "alpha", {-1, -1}, "H, W");
            ReleaseGil release;
            write_alpha_png(p, a.data(), int(a.shape(1)), int(a.shape(0)));
        },
        py::arg("path"), py::arg("alpha"),
        "Writes an (H, W) float image in [0, 1] (e.g. RenderResult.alpha) as an 8-bit grayscale PNG.");
    m.def(
        "write_depth_png",
        [](const PathLike& path, const ArrayLike& depth, const OptionalFloat& near, const OptionalFloat& far) {
            const std::string p = fs_path(path);
            const FloatArray a = as_float_array(depth, "depth", {-1, -1}, "H, W");
            const float nan = std::numeric_limits<float>::quiet_NaN();
            const float lo = near.is_none() ? nan : near.cast<float>(), hi = far.is_none() ? nan : far.cast<float>();
            ReleaseGil release;
            write_depth_png(p, a.data(), int(a.shape(1)), int(a.shape(0)), lo, hi);
        },
        py::arg("path"), py::arg("depth"), py::arg("near") = py::none(), py::arg("far") = py::none(),
        R"doc(
Write a depth map as an 8-bit RGB PNG with the turbo colour map.

t = (depth - near) / (far - near) clamped to [0, 1]: near dark blue, far dark red. Pixels
with depth <= 0 or not finite are black.

Parameters
----------
path : str or os.PathLike
    The .png file, written atomically.
depth : array_like of float, shape (H, W)
    Depth, e.g. ``RenderResult.depth``.
near, far : float, optional
    The range mapped to the colour map; by default the smallest and largest valid depth.

Raises
------
OSError
    When the file cannot be written.)doc");
    m.def(
        "turbo_colormap", [](float t) { return turbo_colormap(t); }, py::arg("t"),
        "The turbo colour map (Google's polynomial fit) at t in [0, 1]: (r, g, b) in [0, 1].");
}

}  // namespace avsplat::python
