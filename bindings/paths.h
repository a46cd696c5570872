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

/// A name read from a file (a PLY element or property name) as str. Such names are bytes, not
/// necessarily UTF-8: invalid bytes become surrogate escapes (as os.fsdecode does), so the name
/// round-trips through os.fsencode and never raises UnicodeDecodeError.
inline pybind11::str file_name_str(const std::string& name) {
    PyObject* s = PyUnicode_DecodeUTF8(name.data(), static_cast<Py_ssize_t>(name.size()), "surrogateescape");
    if (!s) throw pybind11::error_already_set();
    return pybind11::reinterpret_steal<pybind11::str>(s);
}

}  // namespace avsplat::python
