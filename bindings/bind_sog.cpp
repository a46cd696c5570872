// Python bindings of avsplat/io/sog.h: read_sog / write_sog (PlayCanvas SOG).
#include "module.h"
#include "typed_args.h"
#include "paths.h"
#include "release_gil.h"

#include "avsplat/io/sog.h"

namespace avsplat::python {

namespace py = pybind11;

void bind_sog(py::module_& m) {
    m.def(
        "read_sog",
        [](const PathLike& path, std::size_t max_gaussians) {
            const std::string p = fs_path(path);
            SogReadLimits limits;
            limits.max_gaussians = max_gaussians;
            ReleaseGil release;
            return read_sog(p, limits);
        },
        py::arg("path"), py::arg("max_gaussians") = SogReadLimits{}.max_gaussians, R"doc(
Read a PlayCanvas SOG (meta.json version 2 and lossless WebP images).

Parameters
----------
path : str or os.PathLike
    A .sog zip archive, a meta.json file (images beside it) or a folder holding meta.json.
max_gaussians : int
    The largest meta.json "count" accepted (default 2**26); a larger count is an error before
    anything is allocated.

Returns
-------
GaussianCloud
    In file (Morton) order: ``means`` (N, 3), ``scales`` (N, 3) linear, ``rotations`` (N, 4)
    unit w, x, y, z, ``opacities`` (N,), ``sh`` (N, K, 3) with K = (bands + 1)^2, float32; no
    confidence, no extras.

Raises
------
FileError
    An OSError naming the file and the field for anything malformed: not a SOG, meta.json not
    version 2, a missing image, an image smaller than the count, a bad quaternion tag, a
    palette label outside the palette.)doc");
    m.def(
        "write_sog",
        [](const PathLike& path, const GaussianCloud& cloud, int iterations, int palette_size,
           std::uint64_t seed, bool exact_palette) {
            const std::string p = fs_path(path);
            SogWriteOptions options;
            options.iterations = iterations;
            options.palette_size = palette_size;
            options.seed = seed;
            options.exact_palette = exact_palette;
            ReleaseGil release(cloud);
            write_sog(p, cloud, options);
        },
        py::arg("path"), py::arg("cloud"), py::arg("iterations") = SogWriteOptions{}.iterations,
        py::arg("palette_size") = SogWriteOptions{}.palette_size, py::arg("seed") = SogWriteOptions{}.seed,
        py::arg("exact_palette") = SogWriteOptions{}.exact_palette, R"doc(
Write a GaussianCloud as a PlayCanvas SOG (meta.json version 2, lossless WebP images).

Lossy: positions 16 bits per axis after a log transform, rotations 8 bits per smaller
component, scales and colours on 256 shared levels, opacity 8 bits, SH bands 1..3 through the
palette; confidence and extras are dropped, and Gaussians are stored in Morton order.

Parameters
----------
path : str or os.PathLike
    "*.sog" writes a zip archive; "*.json" writes that meta.json with the images beside it; any
    other path is a folder (created if missing) that receives meta.json and the images.
cloud : GaussianCloud
    N Gaussians of SH degree 0..3; validated.
iterations : int
    Lloyd iterations of the SH palette k-means (default 10, splat-transform's).
palette_size : int
    SH palette entries; 0 (default) for splat-transform's rule: the largest power of two <= N,
    at most 65536.
seed : int
    Seeds the palette k-means; equal inputs and seed give identical files whatever the thread
    count.
exact_palette : bool
    False (default): search each vector's palette entry exhaustively for small problems and,
    above 3e10 multiply-adds per pass (above 32,768 SH-3 Gaussians), among the entries of the 8
    groups (of about sqrt(palette)) nearest to it: about 1/20 of the work at 65,536 entries, for
    0.1-4 % more SH-rest error (docs/benchmarks/sog.md). True: always exhaustive (minutes from a
    few 10^5 SH-3 Gaussians on).

Raises
------
ValueError
    For an invalid cloud or argument.
FileError
    An OSError when the file cannot be written.)doc");
}

}  // namespace avsplat::python
