// Python bindings of avsplat/io/: read_ply/write_ply, read_splat/write_splat and the
// extension-dispatching read_gaussians/write_gaussians.
#include "module.h"
#include "numpy_arrays.h"
#include "release_gil.h"
#include "paths.h"

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
Reads a 3DGS PLY file into a GaussianCloud.

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
        py::arg("path"), "Reads .ply (3DGS) or .splat by extension; OSError for other extensions.");
    m.def(
        "write_gaussians",
        [](const py::object& path, const GaussianCloud& cloud) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            write_gaussians(p, cloud);
        },
        py::arg("path"), py::arg("cloud"), "Writes .ply (3DGS) or .splat by extension.");
}

}  // namespace avsplat::python
