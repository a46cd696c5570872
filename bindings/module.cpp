#include "module.h"

#include "avsplat/core/error.h"
#include "avsplat/core/interrupt.h"
#include "release_gil.h"

#include <cstring>
#include <exception>
#include <stdexcept>

namespace py = pybind11;

namespace avsplat::python {

namespace {
unsigned long python_main_thread = 0;
}  // namespace

bool on_python_main_thread() { return PyThread_get_thread_ident() == python_main_thread; }

}  // namespace avsplat::python

PYBIND11_MODULE(_avsplat, m) {
    // Start OpenMP's worker threads now, and have each touch the thread-local data that throwing
    // an exception needs (libstdc++'s, through std::uncaught_exceptions) and the interrupt check's
    // (core/interrupt.h). libgomp ends the process when it cannot create a thread, and glibc when
    // it cannot allocate a loaded library's thread-local data on its first use; under a memory
    // limit set after import (resource.setrlimit, a container's quota) either would otherwise end
    // the process at the first std::bad_alloc in a worker instead of raising MemoryError.
    {
        int started = 0;
#pragma omp parallel reduction(+ : started)
        {
            const avsplat::ScopedInterruptCheck touch_thread_local_data({});
            started += 1 + std::uncaught_exceptions();
        }
        (void)started;
    }
    avsplat::python::python_main_thread =
        py::module_::import("threading").attr("main_thread")().attr("ident").cast<unsigned long>();
    m.doc() = "avsplat: fusion, rendering and I/O of feed-forward 3D Gaussian splats (C++ core)";
    m.attr("__version__") = AVSPLAT_VERSION;
    // C++ exceptions: std::invalid_argument -> ValueError, std::out_of_range -> IndexError,
    // std::bad_alloc -> MemoryError, IOError -> FileError (an OSError), DeviceError -> RuntimeError. Messages
    // can quote bytes from a file or a file name that are not UTF-8; they are decoded with
    // backslash escapes instead of losing the whole message.
    // The Python name is FileError, which shadows no builtin; the package keeps `IOError` as a
    // deprecated alias (avsplat/io.py).
    static py::exception<avsplat::IOError> io_error(m, "FileError", PyExc_OSError);
    io_error.attr("__doc__") = "A file could not be opened, read, parsed or written; the message names the file "
                               "and what is wrong. A subclass of OSError.";
    static py::exception<avsplat::DeviceError> device_error(m, "DeviceError", PyExc_RuntimeError);
    device_error.attr("__doc__") = "A back end (CUDA) failed or is not available in this build or on this machine; "
                                   "the message gives the reason (e.g. the CUDA error string). A subclass of "
                                   "RuntimeError.";
    py::register_exception_translator([](std::exception_ptr p) {
        auto raise = [](PyObject* type, const char* what) {
            PyObject* msg = PyUnicode_DecodeUTF8(what, Py_ssize_t(std::strlen(what)), "backslashreplace");
            PyErr_SetObject(type, msg);
            Py_XDECREF(msg);
        };
        try {
            if (p) std::rethrow_exception(p);
        } catch (const avsplat::IOError& e) {
            raise(io_error.ptr(), e.what());
        } catch (const avsplat::DeviceError& e) {
            raise(device_error.ptr(), e.what());
        } catch (const avsplat::Interrupted&) {
            // The interrupt check ran Python's signal handlers, which set the exception
            // (KeyboardInterrupt for Ctrl-C); keep it.
            if (!PyErr_Occurred()) PyErr_SetNone(PyExc_KeyboardInterrupt);
        } catch (const std::invalid_argument& e) {
            raise(PyExc_ValueError, e.what());
        } catch (const std::out_of_range& e) {
            raise(PyExc_IndexError, e.what());
        }
    });
    avsplat::python::bind_gaussians(m);
    avsplat::python::bind_camera(m);
    avsplat::python::bind_io(m);
    avsplat::python::bind_point_maps(m);
    avsplat::python::bind_render(m);
    avsplat::python::bind_fusion(m);
    avsplat::python::bind_stream(m);
    avsplat::python::bind_simulator(m);
    avsplat::python::bind_view_coverage(m);
    avsplat::python::bind_reduce(m);
    avsplat::python::bind_sog(m);
    avsplat::python::bind_transform(m);
    avsplat::python::bind_simplify(m);
    avsplat::python::bind_lod(m);
    avsplat::python::bind_assist(m);
    avsplat::python::bind_predictions(m);
    avsplat::python::bind_view(m);
    avsplat::python::bind_registration(m);
}
