#include "avsplat/io/gaussian_io.h"

#include "avsplat/core/error.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/splat.h"
#include "avsplat/io/spz.h"
#include "avsplat/io/sog.h"

#include <algorithm>
#include <cctype>

namespace avsplat {

std::string file_extension(const std::string& path) {
    const auto slash = path.find_last_of("/\\");
    const auto dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    std::string ext = path.substr(dot);
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return std::tolower(ch); });
    return ext;
}

GaussianCloud read_gaussians(const std::string& path) {
    if (is_sog(path)) return read_sog(path);
    const std::string ext = file_extension(path);
    if (ext == ".spz" || is_spz_file(path)) return read_spz(path);
    if (ext == ".ply") return read_ply(path);
    if (ext == ".splat") return read_splat(path);
    throw IOError(path + ": unsupported extension '" + ext + "' for Gaussians (.ply, .splat, .spz, .sog)");
}

void write_gaussians(const std::string& path, const GaussianCloud& cloud) {
    const std::string ext = file_extension(path);
    if (ext == ".ply") return write_ply(path, cloud);
    if (ext == ".splat") return write_splat(path, cloud);
    if (ext == ".spz") return write_spz(path, cloud);
    if (ext == ".sog") return write_sog(path, cloud);
    throw IOError(path + ": unsupported extension '" + ext + "' for Gaussians (.ply, .splat, .spz, .sog)");
}

}  // namespace avsplat
