#include "module.h"

#include "avsplat/core/error.h"

namespace py = pybind11;

PYBIND11_MODULE(_avsplat, m) {
    m.doc() = "avsplat: fusion, rendering and I/O of feed-forward 3D Gaussian splats (C++ core)";
    // C++ exceptions: std::invalid_argument/out_of_range -> ValueError/IndexError (pybind11
    // default), IOError -> OSError, DeviceError -> RuntimeError.
    py::register_exception<avsplat::IOError>(m, "IOError", PyExc_OSError)
        .attr("__doc__") = "A file could not be opened, read, parsed or written; the message names the file "
                           "and what is wrong. A subclass of OSError.";
    py::register_exception<avsplat::DeviceError>(m, "DeviceError", PyExc_RuntimeError)
        .attr("__doc__") = "A back end (CUDA) failed or is not available in this build or on this machine; the "
                           "message gives the reason (e.g. the CUDA error string). A subclass of RuntimeError.";
    avsplat::python::bind_gaussians(m);
    avsplat::python::bind_camera(m);
    avsplat::python::bind_io(m);
    avsplat::python::bind_point_maps(m);
    avsplat::python::bind_render(m);
    avsplat::python::bind_fusion(m);
    avsplat::python::bind_stream(m);
#ifdef AVSPLAT_WITH_OPEN3D
    avsplat::python::bind_simulator(m);
#endif
}
