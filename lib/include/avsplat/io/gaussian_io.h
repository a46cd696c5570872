// Reading and writing Gaussians by file extension, as Open3D's ReadPointCloud does:
//   .ply    3DGS PLY (io/ply.h)
//   .splat  antimatter15 .splat (io/splat.h; lossy)
//   .spz    Niantic SPZ (io/spz.h; lossy), also recognised by content whatever the name
//   .sog    PlayCanvas SOG (io/sog.h; lossy); read by content: a zip or folder with meta.json
// Anything else throws avsplat::IOError naming the extension and the supported ones.
#pragma once

#include "avsplat/core/gaussians.h"

#include <string>

namespace avsplat {

GaussianCloud read_gaussians(const std::string& path);
void write_gaussians(const std::string& path, const GaussianCloud& cloud);

/// The lower-case extension of `path` including the dot ("" when there is none).
std::string file_extension(const std::string& path);

}  // namespace avsplat
