// Reading and writing Gaussians in any supported format: reading detects the format from the
// file's content (whatever it is called), writing chooses it from the name, as Open3D's
// ReadPointCloud / WritePointCloud do.
//
//   format                     detected by                               written for names ending
//   3DGS PLY (io/ply.h)        "ply" header without packed_position     .ply
//   compressed PLY             "ply" header whose vertex element has     .compressed.ply
//     (io/compressed_ply.h)    packed_position
//   .splat (io/splat.h)        no other format's signature, and the      .splat
//                              name ends in .splat, or the size is a
//                              non-zero multiple of 32 bytes, the
//                              name does not end in .ply, .spz or .sog,
//                              and the first 256 records look like
//                              .splat (not text; finite, plausible
//                              positions and scales)
//   SPZ                        gzip signature (SPZ 1..3) or "NGSP"       .spz
//   SOG                        zip signature, a folder with meta.json,   .sog
//                              or a file called meta.json
//   glTF binary (io/glb.h)     "glTF" magic                              .glb
//   .ksplat (io/ksplat.h)      no other format's signature, and the      (read only)
//                              name ends in .ksplat or the 4096-byte
//                              header is a plausible .ksplat header
//   LOD set (io/lod_set.h)     a .json file with "lodLevels",            lod-meta.json (one level)
//                              "filenames" and "tree"; reads level 0
// Formats this build cannot read or write throw avsplat::IOError naming the file and the format.
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstdint>
#include <string>

namespace avsplat {

enum class GaussianFormat : std::uint8_t { Ply, CompressedPly, Splat, Spz, Sog, Glb, Ksplat, LodSet };

/// What detect_gaussian_format found.
struct GaussianFormatInfo {
    GaussianFormat format = GaussianFormat::Ply;
    std::string name;     ///< e.g. "3DGS PLY", "compressed PLY"
    std::string version;  ///< e.g. "binary_little_endian 1.0", "2 (colour bounds)"; "" when unknown
};

/// The format of the file (or SOG folder) at `path`, from its content; reads at most the header.
/// Throws IOError naming the file when it cannot be opened or matches no format.
GaussianFormatInfo detect_gaussian_format(const std::string& path);

/// The format write_gaussians writes for `path` (case-insensitive suffix; .compressed.ply before
/// .ply). Throws IOError naming the file and the supported suffixes for any other name.
GaussianFormat gaussian_format_for_name(const std::string& path);

/// The short name of a format: "3DGS PLY", "compressed PLY", ".splat", "SPZ", "SOG", "glTF binary",
/// ".ksplat".
const char* gaussian_format_name(GaussianFormat format);

/// Whether this build reads / writes the format.
bool can_read_gaussian_format(GaussianFormat format);
bool can_write_gaussian_format(GaussianFormat format);

/// Reads Gaussians from `path` in the detected format.
GaussianCloud read_gaussians(const std::string& path);

/// Writes `cloud` to `path` in the format its name says (each format's writer validates it).
void write_gaussians(const std::string& path, const GaussianCloud& cloud);

/// The lower-case extension of `path` including the dot ("" when there is none).
std::string file_extension(const std::string& path);

}  // namespace avsplat
