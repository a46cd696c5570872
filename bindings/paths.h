// File-system paths from Python: str, bytes or any os.PathLike, as open() accepts them.
#pragma once

#include <pybind11/pybind11.h>

#include <string>

namespace avsplat::python {

inline std::string fs_path(const pybind11::object& path) {
    return pybind11::module_::import("os").attr("fsdecode")(path).cast<std::string>();
}

}  // namespace avsplat::python
