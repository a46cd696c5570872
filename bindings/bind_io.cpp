#include "module.h"

#include "avsplat/io/ply.h"

#include <pybind11/stl.h>

namespace avsplat::python {

namespace py = pybind11;

void bind_io(py::module_& m) {
    m.def("read_ply", &read_ply, py::arg("path"),
          "Reads a 3DGS PLY file (binary little/big endian or ASCII, SH degree 0..3) into a "
          "GaussianCloud. Raises OSError naming the file and the problem.",
          py::call_guard<py::gil_scoped_release>());
    m.def("write_ply", &write_ply, py::arg("path"), py::arg("cloud"),
          "Writes a GaussianCloud as binary little-endian 3DGS PLY (opacity as logit, log scales).",
          py::call_guard<py::gil_scoped_release>());
}

}  // namespace avsplat::python
