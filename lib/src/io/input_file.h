// Private: the one check every reader makes before opening its file.
#pragma once

#include "avsplat/core/error.h"

#include <sys/stat.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <string>

namespace avsplat::io {

/// The size of the regular file at `path`. Throws IOError "<path>: cannot open for reading: ..."
/// when it does not exist or cannot be examined, "<path>: is a directory", and "<path>: not a
/// regular file" for a FIFO, a socket or a device: opening a FIFO with no writer would block
/// forever, and /dev/zero would read without end.
inline std::uint64_t regular_file_size(const std::string& path) {
    struct stat st;
    if (::stat(path.c_str(), &st) != 0)
        throw IOError(path + ": cannot open for reading: " + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) throw IOError(path + ": cannot open for reading: is a directory");
    if (!S_ISREG(st.st_mode))
        throw IOError(path + ": cannot open for reading: not a regular file (a FIFO, socket or device)");
    return static_cast<std::uint64_t>(st.st_size);
}

}  // namespace avsplat::io
