#include "avsplat/io/ply.h"

#include "avsplat/error.h"

namespace avsplat {

GaussianCloud read_ply(const std::string& path) {
    throw IOError(path + ": PLY reading is being implemented");
}

void write_ply(const std::string& path, const GaussianCloud& cloud) {
    validate(cloud);
    throw IOError(path + ": PLY writing is being implemented");
}

}  // namespace avsplat
