// PlayCanvas LOD sets ("streamed SOG"): a `lod-meta.json` and SOG version 2 folders beside it, as
// splat-transform 3.7 writes them and the PlayCanvas engine streams them.
//
// lod-meta.json:
//   {"version": 1, "asset": {...}, "count": total over levels, "counts": [per level],
//    "lodLevels": L, "lodErrors": false, "filenames": ["0_0/meta.json", "1_0/meta.json", ...],
//    "tree": node}
//   node  {"bound": {"min": [x, y, z], "max": [x, y, z]}, "children": [node, node]}  (inner), or
//         {"bound": ..., "lods": {"0": {"file": f, "offset": o, "count": c}, "1": ...}}  (leaf)
// A leaf's level l is rows [o, o + c) of the SOG filenames[f]; every SOG holds one level, and its
// rows are the leaves' ranges one after another. The engine culls and picks a level per leaf
// and downloads whole SOGs, so leaves are the unit of view-dependent detail and SOGs the unit of
// transfer. Sets without "version" (written before splat-transform 1.0) read the same way.
//
// What it keeps and loses: each level as SOG keeps it (io/sog.h); the tree is rebuilt on writing.
#pragma once

#include "avsplat/core/gaussians.h"
#include "avsplat/io/sog.h"

#include <array>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace avsplat {

/// What a lod-meta.json declares, checked (read_lod_set_info).
struct LodSetInfo {
    int levels = 0;                       ///< lodLevels
    std::vector<std::size_t> counts;      ///< Gaussians per level, from the tree's leaves
    std::vector<std::string> filenames;   ///< the SOGs, relative to the lod-meta.json's folder
    std::size_t leaves = 0;               ///< leaves of the tree
    int depth = 0;                        ///< the tree's depth (a lone leaf: 0)
    std::array<float, 3> bound_min{}, bound_max{};  ///< the root's bound
};

/// Parses and checks `path` (a lod-meta.json) without reading the SOGs. Throws avsplat::IOError
/// naming the file and the field (with the node path, "tree.children[1].lods.0.file") for
/// invalid JSON, a "version" other than 1, "lodLevels" outside 1..64, a file index outside
/// "filenames", a file name that is absolute or climbs out of the folder (".."), a SOG that holds
/// more than one level, ranges of one SOG that overlap, or "counts" that disagree with the tree.
LodSetInfo read_lod_set_info(const std::string& path);

/// Reads levels of the LOD set at `path` (a lod-meta.json): one cloud per entry of `levels`
/// (negative: from the end, -1 the coarsest), or every level when `levels` is empty. A level's
/// Gaussians are its SOGs' rows in file-index order, as splat-transform 3.7 reads them. Throws
/// avsplat::IOError as read_lod_set_info does, for a level outside 0..lodLevels-1, for a SOG that
/// read_sog refuses, and for a SOG whose count is not the sum of the ranges the tree gives it.
std::vector<GaussianCloud> read_lod_set(const std::string& path, const std::vector<int>& levels = {});

/// Whether `path` is a lod-meta.json, by content: a JSON object with "lodLevels", "filenames" and
/// "tree". Never throws.
bool is_lod_set(const std::string& path);

/// How write_lod_set cuts and encodes the levels.
struct LodWriteOptions {
    /// Most Gaussians (all levels together) of a leaf: nodes holding more are split in two at the
    /// median of their longest axis. Default 16384: leaves of a few thousand Gaussians per level,
    /// which the engine can cull and switch level for finely, without a manifest of 10^5 nodes.
    std::size_t node_size = 16384;
    /// Gaussians of a level after which its current SOG is closed and the next begins (a SOG may
    /// exceed it by one leaf's share). Default 262144: SOGs of about 2.7 MB at SH degree 0, a few
    /// per 10^6 Gaussians, each a compact region (consecutive leaves are neighbours).
    std::size_t chunk_size = 262144;
    /// The SOGs' encoding; morton_order is ignored (rows follow the leaves, each leaf's rows in
    /// Morton order).
    SogWriteOptions sog;
    /// Called with (0, total) before the first SOG and (written, total) after each. Unset: not
    /// called.
    std::function<void(std::size_t, std::size_t)> progress;
};

/// Writes `levels` (level 0 the finest; each validated, all of one SH degree) as a LOD set:
/// `path` is the lod-meta.json (its name must end in .json), and each SOG is a folder
/// "<level>_<k>/" beside it. The tree is a kd-tree over the means of all levels (each leaf holds
/// every level's Gaussians of its region); a leaf's bound is the union of its Gaussians' boxes
/// (half-sides the scales, rotated: splat-transform's bound), an inner node's that of its children. The SOGs are written first and lod-meta.json last
/// (atomically). Throws std::invalid_argument for no levels, an invalid cloud, mixed SH degrees
/// or node_size / chunk_size of 0; avsplat::IOError naming the file that cannot be written.
/// Cost: the SOG encoding of every level (io/sog.h), plus O(N log N) for the tree.
void write_lod_set(const std::string& path, const std::vector<GaussianCloud>& levels,
                   const LodWriteOptions& options = {});

}  // namespace avsplat
