// Python bindings of avsplat/io/: read_ply/write_ply, read_splat/write_splat,
// read_compressed_ply/write_compressed_ply, and read_gaussians/write_gaussians, which detect the
// format from the content when reading and choose it from the name when writing.
#include "module.h"
#include "numpy_arrays.h"
#include "release_gil.h"
#include "paths.h"

#include "avsplat/core/names.h"
#include "avsplat/io/compressed_ply.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/ply_data.h"
#include "avsplat/io/splat.h"

namespace avsplat::python {

namespace py = pybind11;

void bind_io(py::module_& m) {
    m.def(
        "read_ply_data",
        [](const py::object& path) {
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
                        columns[py::str(c.name)] = move_out(std::move(c.values), {n});
                        continue;
                    }
                    std::vector<std::int64_t> offsets(c.offsets.begin(), c.offsets.end());
                    const auto m1 = static_cast<py::ssize_t>(offsets.size());
                    columns[py::str(c.name)] =
                        py::make_tuple(move_out(std::move(c.values), {n}), move_out(std::move(offsets), {m1}));
                }
                elements[py::str(e.name)] = columns;
            }
            return elements;
        },
        py::arg("path"), R"doc(
Reads every element of any PLY file (ASCII, binary little or big endian) as columns.

path  str, bytes or os.PathLike.

Returns {element name: {property name: column}} in file order. A scalar property is a float64
array of the element's row count (float64 holds every PLY type exactly); a list property is a
tuple (values, offsets): row i's items are values[offsets[i]:offsets[i + 1]], offsets int64 of
count + 1 entries. Raises OSError (avsplat.IOError) naming the file and the problem.)doc");
    m.def(
        "read_ply",
        [](const py::object& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_ply(p);
        },
        py::arg("path"), R"doc(
Reads a 3DGS PLY file into a GaussianCloud (a PlayCanvas compressed PLY, recognised by its
packed_position property, is read with read_compressed_ply).

path  str or os.PathLike. Binary little/big endian or ASCII; SH degree 0..3 from the number of
      f_rest properties; properties in any order; float, double and integer types.

Returns a GaussianCloud with means (N, 3), scales (N, 3) linear (exp of the file's log scales),
rotations (N, 4) w, x, y, z as stored, opacities (N,) in [0, 1] (sigmoid of the file's logits),
sh (N, K, 3) with K = (d+1)^2, confidence (N,) when the file has a "confidence" property, and
every other vertex property (normals excepted) as an extra channel (N,), all float32. Values
are not validated: call validate() or sanitize().

Raises OSError (avsplat.IOError) naming the file and the problem when it cannot be read or is
malformed.)doc");
    m.def(
        "write_ply",
        [](const py::object& path, const GaussianCloud& cloud) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            write_ply(p, cloud);
        },
        py::arg("path"), py::arg("cloud"), R"doc(
Writes a GaussianCloud as a binary little-endian 3DGS PLY file (the INRIA layout).

path   str or os.PathLike; an existing file is replaced.
cloud  GaussianCloud of N Gaussians, SH degree d: written as float32 properties x y z nx ny nz
       (zeros) f_dc_0..2 f_rest_0..3*((d+1)^2-1)-1 (channel-major) opacity (logit)
       scale_0..2 (log) rot_0..3 (w, x, y, z), then confidence (if present) and the extra
       channels by name.

Raises ValueError when the cloud fails validate() or an extra channel's name cannot be a PLY
property (spaces, or a 3DGS name such as "opacity"); OSError (avsplat.IOError) naming the file
when it cannot be written.)doc");

    m.def(
        "read_splat",
        [](const py::object& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_splat(p);
        },
        py::arg("path"), R"doc(
Reads an antimatter15 .splat file (32-byte records) into a GaussianCloud of SH degree 0.

Raises OSError (avsplat.IOError) when the size is not a multiple of 32 or a record has a zero
quaternion.)doc");
    m.def(
        "write_splat",
        [](const py::object& path, const GaussianCloud& cloud) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            write_splat(p, cloud);
        },
        py::arg("path"), py::arg("cloud"), R"doc(
Writes a GaussianCloud as an antimatter15 .splat file. Lossy: SH degree 0 only, colours,
opacities and rotations quantised to 8 bits, confidence and extras dropped. Records are ordered
by scale volume times opacity, largest first, as the reference converter does.)doc");
    m.def(
        "read_gaussians",
        [](const py::object& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_gaussians(p);
        },
        py::arg("path"), R"doc(
Reads Gaussians in the format detected from the file's content, whatever it is called: 3DGS
PLY, PlayCanvas compressed PLY, .splat (SPZ and SOG are recognised; this build says so when it
cannot read them). See detect_gaussian_format.

Returns a GaussianCloud. Raises OSError (avsplat.IOError) naming the file when it cannot be
opened, matches no format, or its reader rejects it.)doc");
    m.def(
        "write_gaussians",
        [](const py::object& path, const GaussianCloud& cloud) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            write_gaussians(p, cloud);
        },
        py::arg("path"), py::arg("cloud"), R"doc(
Writes Gaussians in the format the name says: .ply (3DGS PLY), .compressed.ply (PlayCanvas
compressed PLY, Morton order), .splat; .spz and .sog where this build has them.

Raises ValueError when the cloud fails validate(); OSError (avsplat.IOError) naming the file for
any other suffix or when it cannot be written.)doc");

    py::class_<GaussianFormatInfo>(m, "GaussianFormatInfo", R"doc(
What detect_gaussian_format found: format (a word: 'ply', 'compressed_ply', 'splat', 'spz',
'sog'), name (e.g. '3DGS PLY') and version (e.g. 'binary_little_endian 1.0'; '' when unknown).)doc")
        .def_property_readonly("format", [](const GaussianFormatInfo& f) { return name_of(f.format); })
        .def_readonly("name", &GaussianFormatInfo::name)
        .def_readonly("version", &GaussianFormatInfo::version)
        .def("__repr__", [](const GaussianFormatInfo& f) {
            return "GaussianFormatInfo(format='" + name_of(f.format) + "', name='" + f.name + "', version='" + f.version + "')";
        });
    m.def(
        "detect_gaussian_format",
        [](const py::object& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return detect_gaussian_format(p);
        },
        py::arg("path"), R"doc(
The format of a Gaussian file (or SOG folder) from its content; reads only its header.

Returns a GaussianFormatInfo. Raises OSError (avsplat.IOError) naming the file when it cannot be
opened or matches no format.)doc");

    m.def(
        "read_compressed_ply",
        [](const py::object& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_compressed_ply(p);
        },
        py::arg("path"), R"doc(
Reads a PlayCanvas compressed PLY (.compressed.ply: SuperSplat, splat-transform, gsplat).

Returns a GaussianCloud of N Gaussians (the file's order) with SH degree 0..3 from its sh
element: means (N, 3), linear scales (N, 3), unit rotations (N, 4) w, x, y, z, opacities (N,),
sh (N, K, 3), float32, dequantised as splat-transform does. Raises OSError (avsplat.IOError)
naming the file, element, property and row when it is malformed (missing elements or
properties, a chunk count other than ceil(N / 256), non-finite bounds, truncation).)doc");
    m.def(
        "write_compressed_ply",
        [](const py::object& path, const GaussianCloud& cloud, bool morton) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            write_compressed_ply(p, cloud, morton);
        },
        py::arg("path"), py::arg("cloud"), py::arg("morton_order") = true, R"doc(
Writes a GaussianCloud as a PlayCanvas compressed PLY, quantised as splat-transform does: per
chunk of 256 Gaussians float bounds; position and log scale 11/10/11 bits, rotation smallest
three 2+10+10+10, colour and opacity 8 bits each, SH bands 1..3 one byte per coefficient (range
[-4, 4]). Confidence and extras are dropped.

morton_order  True (default): Gaussians are written in splat-transform's Morton order (see
              morton_order()); False keeps the cloud's order.
Raises ValueError when the cloud fails validate(); OSError (avsplat.IOError) naming the file.)doc");
    m.def(
        "morton_order",
        [](const GaussianCloud& cloud) {
            std::vector<std::size_t> order;
            {
                ReleaseGil release;
                order = morton_order(cloud);
            }
            std::vector<std::int64_t> out(order.begin(), order.end());
            const auto n = static_cast<py::ssize_t>(out.size());
            return move_out(std::move(out), {n});
        },
        py::arg("cloud"), R"doc(
The order write_compressed_ply writes Gaussians in: int64 (N,), order[i] is the cloud index of
the file's i-th Gaussian (splat-transform's Morton sort of the means, 10 bits per axis, ties in
input order, buckets of more than 256 equal codes sorted again).)doc");
}

}  // namespace avsplat::python
