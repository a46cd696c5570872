// ReleaseGil: what every long binding uses in place of py::gil_scoped_release. Besides releasing
// the GIL it installs an interrupt check (avsplat/core/interrupt.h) that, on Python's main thread,
// takes the GIL back briefly and runs Python's signal handlers, so that Ctrl-C stops a long C++
// call within about a second. The call then throws avsplat::Interrupted, which module.cpp turns
// into the KeyboardInterrupt the handler raised. Other threads get no check: Python delivers
// signals to the main thread only.
#pragma once

#include "avsplat/core/interrupt.h"

#include <pybind11/pybind11.h>

#include <functional>

namespace avsplat::python {

/// True on the thread Python runs its signal handlers on (call with the GIL held).
bool on_python_main_thread();

class ReleaseGil {
public:
    ReleaseGil() : interrupt_(on_python_main_thread() ? check_signals : std::function<bool()>()) {}

private:
    static bool check_signals() {
        pybind11::gil_scoped_acquire gil;
        return PyErr_CheckSignals() != 0;
    }
    ScopedInterruptCheck interrupt_;   // installed first, removed last
    pybind11::gil_scoped_release release_;
};

}  // namespace avsplat::python
