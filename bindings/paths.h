// File-system paths from Python: str, bytes or any os.PathLike, as open() accepts them.
#pragma once

#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>

namespace avsplat::python {

/// The path's bytes as the file system sees them: os.fsencode keeps names that are not valid
/// UTF-8 (surrogate escapes) intact. A NUL byte would silently cut the path short in the C
/// library, so it is refused with ValueError, as open() does.
inline std::string fs_path(const pybind11::object& path) {
    auto bytes = pybind11::module_::import("os").attr("fsencode")(path).cast<pybind11::bytes>();
    std::string p = bytes;
    if (p.find('\0') != std::string::npos)
        throw pybind11::value_error("path contains a NUL byte: " +
                                    pybind11::repr(path).cast<std::string>());
    return p;
}

}  // namespace avsplat::python
