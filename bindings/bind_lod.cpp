// Python bindings of avsplat/io/lod_set.h and avsplat/reduce/build_lod.h: PlayCanvas LOD sets.
#include "module.h"
#include "paths.h"
#include "release_gil.h"
#include "typed_args.h"

#include "avsplat/io/lod_set.h"
#include "avsplat/reduce/build_lod.h"
#include "avsplat/reduce/names.h"

#include <pybind11/stl.h>

#include <sstream>

namespace avsplat::python {

namespace py = pybind11;

void bind_lod(py::module_& m) {
    py::class_<LodSetInfo>(m, "LodSetInfo", "What a lod-meta.json declares: levels, counts, chunks and tree.")
        .def_readonly("levels", &LodSetInfo::levels, "lodLevels")
        .def_readonly("counts", &LodSetInfo::counts, "Gaussians per level (from the tree's leaves)")
        .def_readonly("filenames", &LodSetInfo::filenames, "the SOG chunks, relative to the lod-meta.json")
        .def_readonly("leaves", &LodSetInfo::leaves, "leaves of the tree")
        .def_readonly("depth", &LodSetInfo::depth, "depth of the tree (a lone leaf: 0)")
        .def("__repr__", [](const LodSetInfo& i) {
            std::ostringstream os;
            os << "LodSetInfo(levels=" << i.levels << ", counts=[";
            for (std::size_t l = 0; l < i.counts.size(); ++l) os << (l ? ", " : "") << i.counts[l];
            os << "], chunks=" << i.filenames.size() << ", leaves=" << i.leaves << ")";
            return os.str();
        });
    m.def(
        "read_lod_set_info",
        [](const PathLike& path) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_lod_set_info(p);
        },
        py::arg("path"), R"doc(
Parse and check a PlayCanvas LOD set's lod-meta.json without reading its SOG chunks.

Returns
-------
LodSetInfo
    ``levels``, ``counts`` (per level), ``filenames``, ``leaves``, ``depth``.

Raises
------
FileError
    Naming the file and the field (with the node's path in the tree) for anything malformed.)doc");
    m.def(
        "read_lod_set",
        [](const PathLike& path, const std::vector<int>& levels) {
            const std::string p = fs_path(path);
            ReleaseGil release;
            return read_lod_set(p, levels);
        },
        py::arg("path"), py::arg("levels") = std::vector<int>{}, R"doc(
Read levels of a PlayCanvas LOD set (lod-meta.json and SOG chunks), as splat-transform's -L.

Parameters
----------
path : str or os.PathLike
    The lod-meta.json.
levels : list of int
    The levels to read (negative from the end: -1 the coarsest); empty (default) for all.

Returns
-------
list of GaussianCloud
    One cloud per level asked for, its rows the level's SOG chunks in file order.

Raises
------
FileError
    Naming the file and the field for a malformed lod-meta.json, a level out of range or a
    chunk that cannot be read or disagrees with the tree.)doc");
    m.def(
        "write_lod_set",
        [](const PathLike& path, const std::vector<GaussianCloud>& levels, std::size_t node_size,
           std::size_t chunk_size, int iterations) {
            const std::string p = fs_path(path);
            LodWriteOptions o;
            o.node_size = node_size;
            o.chunk_size = chunk_size;
            o.sog.iterations = iterations;
            ReleaseGil release;
            write_lod_set(p, levels, o);
        },
        py::arg("path"), py::arg("levels"), py::arg("node_size") = LodWriteOptions{}.node_size,
        py::arg("chunk_size") = LodWriteOptions{}.chunk_size, py::arg("iterations") = SogWriteOptions{}.iterations,
        R"doc(
Write clouds as the levels of a PlayCanvas LOD set (lod-meta.json and SOG chunks).

Parameters
----------
path : str or os.PathLike
    The lod-meta.json to write (must end in .json); the chunks go beside it as folders
    "<level>_<k>/".
levels : list of GaussianCloud
    Level 0 (the finest) first; all of one SH degree.
node_size : int
    Most Gaussians (all levels together) of a tree leaf (default 16384).
chunk_size : int
    Gaussians of a level after which its next SOG chunk begins (default 262144).
iterations : int
    Lloyd iterations of each chunk's SH palette (write_sog).

Raises
------
ValueError
    No levels, an invalid cloud, mixed SH degrees, a size of 0.
FileError
    A file that cannot be written.)doc");

    py::class_<LodBuild>(m, "LodBuild", "The levels build_lod made, and the time and error of each.")
        .def_readonly("levels", &LodBuild::levels, "GaussianCloud per level, level 0 (the input) first")
        .def_readonly("seconds", &LodBuild::seconds, "seconds to make each level (0 for level 0)")
        .def_readonly("errors", &LodBuild::errors,
                      "rendered RMSE of each level against the previous one at the cameras; nan without cameras")
        .def("__repr__", [](const LodBuild& b) {
            std::ostringstream os;
            os << "LodBuild(counts=[";
            for (std::size_t l = 0; l < b.levels.size(); ++l) os << (l ? ", " : "") << b.levels[l].size();
            os << "])";
            return os.str();
        });
    m.def(
        "build_lod",
        [](const GaussianCloud& cloud, const OptionalPathLike& path, int levels, double ratio, std::size_t coarsest,
           std::size_t node_size, std::size_t chunk_size, const std::string& method, const OptionalCameras& cameras) {
            BuildLodOptions o;
            o.levels = levels;
            o.ratio = ratio;
            o.coarsest = coarsest;
            o.method = parse_simplify_method(method, "method");
            LodWriteOptions w;
            w.node_size = node_size;
            w.chunk_size = chunk_size;
            std::vector<Camera> cams;
            if (!cameras.is_none()) cams = cameras.cast<std::vector<Camera>>();
            const bool write = !path.is_none();
            const std::string p = write ? fs_path(path) : std::string();
            ReleaseGil release(cloud);
            return write ? build_lod(cloud, p, o, w, cams) : build_lod_levels(cloud, o, cams);
        },
        py::arg("cloud"), py::arg("path") = py::none(), py::arg("levels") = BuildLodOptions{}.levels,
        py::arg("ratio") = BuildLodOptions{}.ratio, py::arg("coarsest") = BuildLodOptions{}.coarsest,
        py::arg("node_size") = LodWriteOptions{}.node_size, py::arg("chunk_size") = LodWriteOptions{}.chunk_size,
        py::arg("method") = to_string(BuildLodOptions{}.method), py::arg("cameras") = py::none(), R"doc(
Build a level-of-detail set: level 0 the cloud, each further level the previous one simplified
whole (no seams at node borders) to `ratio` of its count; written as a PlayCanvas LOD set when
`path` is given.

Parameters
----------
cloud : GaussianCloud
    The scene (level 0).
path : str or os.PathLike, optional
    The lod-meta.json to write (see write_lod_set); None: only make the levels.
levels : int
    Levels including level 0, 1..64; 0 (default) until the coarsest holds at most `coarsest`.
ratio : float
    Each level's count over the previous one's, in (0, 1); default 0.5.
coarsest : int
    With levels=0: the most Gaussians of the coarsest level (default 65536).
node_size, chunk_size : int
    As write_lod_set.
method : {"merge", "voxel"}
    The simplify method.
cameras : list of Camera, optional
    Passed to simplify, which then measures each level's rendered error against the previous.

Returns
-------
LodBuild
    ``levels``, ``seconds``, ``errors``.

Raises
------
ValueError
    An invalid cloud or option.
FileError
    A file that cannot be written.)doc");
}

}  // namespace avsplat::python
