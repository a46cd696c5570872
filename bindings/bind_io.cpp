// Python bindings of avsplat/io/: read_ply/write_ply, read_splat/write_splat,
// read_compressed_ply/write_compressed_ply, and read_gaussians/write_gaussians, which detect the
// format from the content when reading and choose it from the name when writing.
#include "module.h"
#include "typed_args.h"
#include "numpy_arrays.h"
#include "release_gil.h"
#include "paths.h"

#include "avsplat/core/names.h"
#include "avsplat/io/names.h"
#include "avsplat/io/compressed_ply.h"
#include "avsplat/io/glb.h"
#include "avsplat/io/ksplat.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/ply_data.h"
#include "avsplat/io/splat.h"
#include "avsplat/io/spz.h"

#include <memory>

namespace avsplat::python {

namespace py = pybind11;

void bind_io(py::module_& m) {
    m.def(
        "read_ply_data",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            PlyData data;
            {
                ReleaseGil release;
                data = read_ply_data(p);
            }
            py::dict elements;
            for (PlyElement& e : data.elements) {
                py::dict columns;
                for (PlyColumn& c : e.columns) {
                    const auto n = static_cast<py::ssize_t>(c.values.size());
                    if (!c.is_list) {
                        columns[file_name_str(c.name)] = move_out(std::move(c.values), {n});
                        continue;
                    }
                    std::vector<std::int64_t> offsets(c.offsets.begin(), c.offsets.end());
                    const auto m1 = static_cast<py::ssize_t>(offsets.size());
                    columns[file_name_str(c.name)] =
                        py::make_tuple(move_out(std::move(c.values), {n}), move_out(std::move(offsets), {m1}));
                }
                elements[file_name_str(e.name)] = columns;
            }
            return elements;
        },
        py::arg("path"), R"doc(
Read every element of any PLY file (ASCII, binary little or big endian) as columns.

Parameters
----------
path : str, bytes or os.PathLike
    The PLY file.

Returns
-------
dict
    {element name: {property name: column}} in file order. A scalar property is a float64
    array of the element's row count (float64 holds every PLY type exactly); a list property
    is a tuple (values, offsets): row i's items are ``values[offsets[i]:offsets[i + 1]]``,
    offsets int64 of count + 1 entries.

Raises
------
FileError
    An OSError naming the file and the problem.)doc");
    m.def(
        "read_ply",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_ply(p);
        },
        py::arg("path"), R"doc(
Read a 3DGS PLY file into a GaussianCloud.

A PlayCanvas compressed PLY, recognised by its packed_position property, is read with
``read_compressed_ply``.

Parameters
----------
path : str or os.PathLike
    Binary little/big endian or ASCII; SH degree 0..3 from the number of f_rest properties;
    properties in any order; float, double and integer types.

Returns
-------
GaussianCloud
    ``means`` (N, 3), ``scales`` (N, 3) linear (exp of the file's log scales), ``rotations``
    (N, 4) w, x, y, z as stored, ``opacities`` (N,) in [0, 1] (sigmoid of the file's logits),
    ``sh`` (N, K, 3) with K = (d+1)^2, ``confidence`` (N,) when the file has a "confidence"
    property, and every other vertex property (normals excepted) as an extra channel (N,), all
    float32. Values are not validated: call ``validate()`` or ``sanitize()``.

Raises
------
FileError
    An OSError naming the file and the problem when it cannot be read or is malformed.)doc");
    m.def(
        "write_ply",
        [](const PathLike& path, const GaussianCloud& cloud) {
            const std::string p = fs_path(path);
            ReleaseGil release(cloud);
            write_ply(p, cloud);
        },
        py::arg("path"), py::arg("cloud"), R"doc(
Write a GaussianCloud as a binary little-endian 3DGS PLY file (the INRIA layout), atomically.

Parameters
----------
path : str or os.PathLike
    The file; an existing file is replaced.
cloud : GaussianCloud
    N Gaussians of SH degree d, written as float32 properties x y z nx ny nz (zeros)
    f_dc_0..2 f_rest_0..3*((d+1)^2-1)-1 (channel-major) opacity (logit) scale_0..2 (log)
    rot_0..3 (w, x, y, z), then confidence (if present) and the extra channels by name.

Raises
------
ValueError
    When the cloud fails ``validate()`` or an extra channel's name cannot be a PLY property
    (spaces, or a 3DGS name such as "opacity").
FileError
    An OSError naming the file when it cannot be written.)doc");

    py::class_<GaussianPlyWriter>(m, "GaussianPlyWriter", R"doc(
Write a 3DGS PLY file whose Gaussians arrive in parts, never holding the whole cloud.

``GaussianPlyWriter(path)``; ``append(cloud)`` for each part; ``commit()``. The file is byte for
byte what ``write_ply`` writes for the parts concatenated, and replaces `path` only at
``commit()`` (atomically; without commit, e.g. on an exception in a ``with`` block, `path` is
left as it was). The first part fixes the SH degree, confidence and extra channels. The encoded
rows wait in an unlinked scratch file beside `path` until ``commit()`` writes the header (plan
for twice the output's size).

Parameters
----------
path : str or os.PathLike
    The PLY file to write.

Raises
------
ValueError
    For an invalid part or one whose schema differs from the first.
FileError
    An OSError naming the file.

Examples
--------
>>> with avsplat.GaussianPlyWriter("fused.ply") as out:
...     stream.finish_gaussians(sink=lambda block: out.append(block.cloud)))doc")
        .def(py::init([](const PathLike& path) { return std::make_unique<GaussianPlyWriter>(fs_path(path)); }),
             py::arg("path"))
        .def(
            "append",
            [](GaussianPlyWriter& w, const GaussianCloud& part) {
                ReleaseGil release(part);
                w.append(part);
            },
            py::arg("cloud"), "Appends the Gaussians of `cloud`.")
        .def(
            "commit",
            [](GaussianPlyWriter& w) {
                ReleaseGil release;
                w.commit();
            },
            "Writes the header and rows and renames the file into place. Call once.")
        .def_property_readonly("size", &GaussianPlyWriter::size, "Gaussians appended so far")
        .def("__len__", &GaussianPlyWriter::size)
        .def("__repr__",
             [](const GaussianPlyWriter& w) {
                 return "GaussianPlyWriter(" + py::repr(py::str(w.path())).cast<std::string>() +
                        ", size=" + std::to_string(w.size()) + ")";
             })
        .def("__enter__", [](GaussianPlyWriter& w) -> GaussianPlyWriter& { return w; },
             py::return_value_policy::reference)
        .def("abort", &GaussianPlyWriter::abort,
             "Removes the temporary and scratch files now, leaving `path` as it was; append() and commit()\n"
             "then raise RuntimeError. A `with` block that raises aborts.")
        .def("__exit__", [](GaussianPlyWriter& w, const AnyValue& type, const AnyValue&, const AnyValue&) {
            if (type.is_none()) {
                ReleaseGil release;
                w.commit();
            } else {
                w.abort();  // at once, not when the writer is collected
            }
            return false;
        });

    m.def(
        "read_splat",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_splat(p);
        },
        py::arg("path"), R"doc(
Read an antimatter15 .splat file (32-byte records) into a GaussianCloud of SH degree 0.

Parameters
----------
path : str or os.PathLike
    The .splat file.

Returns
-------
GaussianCloud
    N Gaussians, SH degree 0.

Raises
------
FileError
    An OSError when the size is not a multiple of 32 or a record has a zero quaternion.)doc");
    m.def(
        "write_splat",
        [](const PathLike& path, const GaussianCloud& cloud) {
            const std::string p = fs_path(path);
            ReleaseGil release(cloud);
            write_splat(p, cloud);
        },
        py::arg("path"), py::arg("cloud"), R"doc(
Write a GaussianCloud as an antimatter15 .splat file, atomically.

Lossy: SH degree 0 only; colours, opacities and rotations quantised to 8 bits; confidence and
extras dropped. Records are ordered by scale volume times opacity, largest first, as the
reference converter does.

Parameters
----------
path : str or os.PathLike
    The .splat file.
cloud : GaussianCloud
    N Gaussians.)doc");
    m.def(
        "read_spz",
        [](const PathLike& path, const std::string& coordinate_system) {
            const std::string p = fs_path(path);
            SpzReadOptions o;
            o.coordinate_system = parse_spz_coordinate_system(coordinate_system);
            ReleaseGil release;
            return read_spz(p, o);
        },
        py::arg("path"), py::arg("coordinate_system") = "rub", R"doc(
Read a Niantic SPZ file (version 2, 3 or 4) into a GaussianCloud in avsplat's axes.

avsplat's axes are OpenCV's: x right, y down, z forward.

Parameters
----------
path : str or os.PathLike
    The .spz file.
coordinate_system : str
    The axes the file's data is stored in: "rub" (the SPZ specification's, the default), or
    "rdf" for files written by splat-transform 3.7 (which stores PLY axes); any of ldb rdb lub
    rub ldf rdf luf ruf. A coordinate-system extension in the file overrides it.

Returns
-------
GaussianCloud
    ``means`` (N, 3), linear ``scales`` (N, 3), unit ``rotations`` (N, 4) w, x, y, z,
    ``opacities`` (N,), ``sh`` (N, K, 3) of the file's SH degree (band 4 of degree-4 files is
    dropped), all float32, and ``antialiased`` from the header's flag (render with
    ``antialiased=cloud.antialiased``).

Raises
------
FileError
    An OSError naming the file and the field for a malformed, truncated or lying file (sizes
    are checked before allocating; decompression stops at the size the header implies).
ValueError
    For an unknown `coordinate_system`.)doc");
    m.def(
        "write_spz",
        [](const PathLike& path, const GaussianCloud& cloud, int version, const std::string& coordinate_system,
           int fractional_bits) {
            const std::string p = fs_path(path);
            SpzWriteOptions o;
            o.version = version;
            o.coordinate_system = parse_spz_coordinate_system(coordinate_system);
            o.fractional_bits = fractional_bits;
            ReleaseGil release(cloud);
            write_spz(p, cloud, o);
        },
        py::arg("path"), py::arg("cloud"), py::arg("version") = 4, py::arg("coordinate_system") = "rub",
        py::arg("fractional_bits") = -1, R"doc(
Write a GaussianCloud as a Niantic SPZ file, atomically.

Lossy: positions to 2^-fractional_bits, log scales to 1/16, rotations to 9 bits (smallest
three; version 2: x, y, z to 8 bits), opacity and DC colour to 8 bits, SH band 1 to 5 bits and bands 2-3 to 4 bits;
confidence and extras dropped. ``cloud.antialiased`` sets the header's antialiased flag.

Parameters
----------
path : str or os.PathLike
    The .spz file.
cloud : GaussianCloud
    N Gaussians.
version : {4, 3, 2}
    4: per-attribute ZSTD streams (the default); 3: one gzip stream, for readers that predate
    version 4; 2: as 3 but rotations as x, y, z at 8 bits each, for readers that predate 3.
coordinate_system : str
    The axes to store: "rub" (the specification's, the default); see ``read_spz``.
fractional_bits : int
    Of the 24-bit fixed-point positions, 0..23; -1: 12 (1/4096 unit), or fewer when the
    largest absolute coordinate needs them.

Raises
------
ValueError
    For an invalid cloud, a version other than 2, 3 or 4, or a coordinate that does not fit
    24 bits.
FileError
    An OSError when the file cannot be written.)doc");
    m.def(
        "read_glb",
        [](const PathLike& path, bool log_scales) {
            const std::string p = fs_path(path);
            GlbOptions o;
            o.log_scales = log_scales;
            ReleaseGil release;
            return read_glb(p, o);
        },
        py::arg("path"), py::arg("log_scales") = false, R"doc(
Read the Gaussians of a binary glTF (.glb) with the KHR_gaussian_splatting extension.

The layout is splat-transform 3.7's (POSITION, KHR_gaussian_splatting:ROTATION x, y, z, w,
SCALE, OPACITY and SH_DEGREE_l_COEF_n attributes); the extension's normalized integer types,
interleaved buffer views and several Gaussian primitives (concatenated) are read too. glTF's
axes (+Y up, +Z forward, +X left) become avsplat's (x right, y down, z forward): a 180-degree turn
about z, as splat-transform makes between PLY and .glb.

Parameters
----------
path : str or os.PathLike
    The .glb file.
log_scales : bool
    False (default): SCALE holds linear scales, as splat-transform 3.7 writes; True: it holds
    log(scale), as the extension's review draft says.

Returns
-------
GaussianCloud
    float32 ``means`` (N, 3), ``scales`` (N, 3), ``rotations`` (N, 4) w, x, y, z as stored,
    ``opacities`` (N,), ``sh`` (N, K, 3) of the highest SH degree given whole (0..3).

Raises
------
FileError
    An OSError naming the file and the field (accessor, buffer view, attribute) for a malformed,
    truncated or unsupported file (sparse accessors, external buffers, node transforms, SH
    degrees given in part); accessors are checked against the binary chunk before allocating.)doc");
    m.def(
        "write_glb",
        [](const PathLike& path, const GaussianCloud& cloud, bool log_scales) {
            const std::string p = fs_path(path);
            GlbOptions o;
            o.log_scales = log_scales;
            ReleaseGil release(cloud);
            write_glb(p, cloud, o);
        },
        py::arg("path"), py::arg("cloud"), py::arg("log_scales") = false, R"doc(
Write a GaussianCloud as binary glTF (.glb) with KHR_gaussian_splatting, atomically.

The layout splat-transform 3.7 writes: float32 positions, rotations, scales, opacities and SH
coefficients (degree 0..3, lossless), plus a COLOR_0 fallback (8-bit colour and opacity) for
viewers without the extension, in glTF's axes (the scene turned 180 degrees about z, as
splat-transform writes PLY input). ``antialiased``, confidence and extras are dropped.

Parameters
----------
path : str or os.PathLike
    The .glb file.
cloud : GaussianCloud
    N Gaussians.
log_scales : bool
    False (default): linear scales, as splat-transform 3.7; True: log(scale), as the extension's
    review draft says.

Raises
------
ValueError
    When the cloud fails ``validate()`` or needs more than a GLB's 4 GiB.
FileError
    An OSError when the file cannot be written.)doc");
    m.def(
        "read_ksplat",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_ksplat(p);
        },
        py::arg("path"), R"doc(
Read a .ksplat file (mkkellogg's GaussianSplats3D), compression level 0, 1 or 2.

Parameters
----------
path : str or os.PathLike
    The .ksplat file.

Returns
-------
GaussianCloud
    float32 ``means`` (N, 3), linear ``scales`` (N, 3), ``rotations`` (N, 4) w, x, y, z as
    stored, ``opacities`` (N,) from the 8-bit alpha, ``sh`` (N, K, 3) of the highest section SH
    degree (0..2; DC from the 8-bit colour), in the file's section and record order.

Raises
------
FileError
    An OSError naming the file and the field (``sections[i].<field>``) for a malformed,
    truncated or unsupported file; every section is checked against the file size before
    allocating.)doc");
    m.def(
        "read_spz_header",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            SpzHeader h;
            {
                ReleaseGil release;
                h = read_spz_header(p);
            }
            py::dict d;
            d["version"] = h.version;
            d["count"] = h.count;
            d["sh_degree"] = h.sh_degree;
            d["fractional_bits"] = h.fractional_bits;
            d["antialiased"] = h.antialiased;
            return d;
        },
        py::arg("path"),
        "The header of an SPZ file as a dict: version, count, sh_degree (as stored, 0..4), fractional_bits, "
        "antialiased. Raises OSError naming the file when it is not SPZ.");
    m.def(
        "read_gaussians",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_gaussians(p);
        },
        py::arg("path"), R"doc(
Read Gaussians in the format detected from the file's content, whatever it is called.

3DGS PLY, PlayCanvas compressed PLY, .splat, Niantic SPZ (v2-4), PlayCanvas SOG (a .sog zip, a
folder with meta.json, or the meta.json). See ``detect_gaussian_format``.

Parameters
----------
path : str or os.PathLike
    The file or SOG folder.

Returns
-------
GaussianCloud
    N Gaussians.

Raises
------
FileError
    An OSError naming the file when it cannot be opened, matches no format, or its reader
    rejects it.)doc");
    m.def(
        "write_gaussians",
        [](const PathLike& path, const GaussianCloud& cloud) {
            const std::string p = fs_path(path);
            ReleaseGil release(cloud);
            write_gaussians(p, cloud);
        },
        py::arg("path"), py::arg("cloud"), R"doc(
Write Gaussians in the format the name says, atomically.

.ply (3DGS PLY), .compressed.ply (PlayCanvas compressed PLY, Morton order), .splat, .spz (SPZ
version 4, RUB axes), .sog (SOG zip).

Parameters
----------
path : str or os.PathLike
    The file; its suffix chooses the format.
cloud : GaussianCloud
    N Gaussians.

Raises
------
ValueError
    When the cloud fails ``validate()``.
FileError
    An OSError naming the file for any other suffix or when it cannot be written.)doc");

    py::class_<GaussianFormatInfo>(m, "GaussianFormatInfo", R"doc(
What ``detect_gaussian_format`` found.

Attributes
----------
format : str
    A word: 'ply', 'compressed_ply', 'splat', 'spz' or 'sog'.
name : str
    E.g. '3DGS PLY'.
version : str
    E.g. 'binary_little_endian 1.0'; '' when unknown.)doc")
        .def_property_readonly("format", [](const GaussianFormatInfo& f) { return name_of(f.format); })
        .def_readonly("name", &GaussianFormatInfo::name)
        .def_readonly("version", &GaussianFormatInfo::version)
        .def("__repr__", [](const GaussianFormatInfo& f) {
            return "GaussianFormatInfo(format='" + name_of(f.format) + "', name='" + f.name + "', version='" + f.version + "')";
        });
    m.def(
        "detect_gaussian_format",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return detect_gaussian_format(p);
        },
        py::arg("path"), R"doc(
Detect the format of a Gaussian file (or SOG folder) from its content; reads only its header.

Parameters
----------
path : str or os.PathLike
    The file or SOG folder.

Returns
-------
GaussianFormatInfo
    ``format``, ``name`` and ``version``.

Raises
------
FileError
    An OSError naming the file when it cannot be opened or matches no format.)doc");

    m.def(
        "read_compressed_ply",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_compressed_ply(p);
        },
        py::arg("path"), R"doc(
Read a PlayCanvas compressed PLY (.compressed.ply: SuperSplat, splat-transform, gsplat).

Parameters
----------
path : str or os.PathLike
    The file.

Returns
-------
GaussianCloud
    N Gaussians in the file's order with SH degree 0..3 from its sh element: ``means`` (N, 3),
    linear ``scales`` (N, 3), unit ``rotations`` (N, 4) w, x, y, z, ``opacities`` (N,), ``sh``
    (N, K, 3), float32, dequantised as splat-transform does.

Raises
------
FileError
    An OSError naming the file, element, property and row when it is malformed (missing
    elements or properties, a chunk count other than ceil(N / 256), non-finite bounds,
    truncation).)doc");
    m.def(
        "write_compressed_ply",
        [](const PathLike& path, const GaussianCloud& cloud, bool morton) {
            const std::string p = fs_path(path);
            ReleaseGil release(cloud);
            write_compressed_ply(p, cloud, morton);
        },
        py::arg("path"), py::arg("cloud"), py::arg("morton_order") = true, R"doc(
Write a GaussianCloud as a PlayCanvas compressed PLY, quantised as splat-transform does.

Per chunk of 256 Gaussians: float bounds; position and log scale 11/10/11 bits, rotation
smallest three 2+10+10+10, colour and opacity 8 bits each, SH bands 1..3 one byte per
coefficient (range [-4, 4]). Confidence and extras are dropped.

Parameters
----------
path : str or os.PathLike
    The file.
cloud : GaussianCloud
    N Gaussians.
morton_order : bool
    True (default): Gaussians are written in splat-transform's Morton order (see
    ``morton_order``); False keeps the cloud's order.

Raises
------
ValueError
    When the cloud fails ``validate()``.
FileError
    An OSError naming the file.)doc");
    m.def(
        "morton_order",
        [](const GaussianCloud& cloud, const OptionalArrayLike& rows) {
            std::vector<std::size_t> given;
            if (!rows.is_none()) {
                const auto idx = py::array_t<long long, py::array::c_style | py::array::forcecast>::ensure(rows);
                if (!idx || idx.ndim() != 1 || py::array(rows).dtype().kind() == 'b')
                    throw py::value_error("morton_order: rows must be a 1-D array of integer row indices");
                given.resize(std::size_t(idx.size()));
                for (py::ssize_t k = 0; k < idx.size(); ++k) {
                    const long long x = idx.data()[k];
                    if (x < 0) throw py::index_error("morton_order: rows[" + std::to_string(k) + "] is negative");
                    given[std::size_t(k)] = static_cast<std::size_t>(x);
                }
            }
            std::vector<std::size_t> order;
            {
                ReleaseGil release(cloud);
                order = rows.is_none() ? morton_order(cloud) : morton_order(cloud, std::move(given));
            }
            std::vector<std::int64_t> out(order.begin(), order.end());
            const auto n = static_cast<py::ssize_t>(out.size());
            return move_out(std::move(out), {n});
        },
        py::arg("cloud"), py::arg("rows") = py::none(), R"doc(
The order ``write_compressed_ply`` writes Gaussians in.

splat-transform's Morton sort of the means: 10 bits per axis, ties in input order, buckets of
more than 256 equal codes sorted again.

Parameters
----------
cloud : GaussianCloud
    N Gaussians.
rows : array_like of int, shape (M,), optional
    Row indices (a permutation or a subset): the same sort over those rows and the bounds of
    their means, ties in the order of `rows`; the result is then row indices, the same as
    ``rows[morton_order(cloud.select(rows))]`` without copying the cloud.

Returns
-------
ndarray, shape (N,) or (M,), int64
    order[i] is the cloud index of the file's i-th Gaussian.

Raises
------
IndexError
    For a negative or out-of-range row.)doc");
}

}  // namespace avsplat::python
