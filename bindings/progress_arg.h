// progress= of the long bindings: a Python callable(done, total), or None, installed as the
// progress callback (avsplat/core/progress.h) of the C++ call. Construct it with the GIL held
// and before ReleaseGil; the callback takes the GIL only while the Python function runs, and an
// exception it raises stops the call and propagates from it as that exception.
#pragma once

#include "avsplat/core/progress.h"

#include "typed_args.h"

#include <pybind11/pybind11.h>

#include <cstdint>
#include <string>

namespace avsplat::python {

class PythonProgress {
public:
    explicit PythonProgress(const OptionalCallable& progress) : scope_(callback(progress)) {}

    /// The docstring lines of the argument; `unit` says what done and total count.
    static std::string doc(const std::string& unit) {
        return "progress : callable, optional\n    Called as progress(done, total) with the " + unit +
               ", from the calling thread: first (0, total), done never decreases, and (total, total) when the "
               "work is complete. An exception it raises stops the work and is raised from this call.\n";
    }

private:
    static ProgressCallback callback(const OptionalCallable& progress) {
        if (progress.is_none()) return {};
        if (!PyCallable_Check(progress.ptr()))
            throw pybind11::type_error("progress: expected a callable(done, total) or None, got " +
                                       std::string(Py_TYPE(progress.ptr())->tp_name));
        // The caller's reference keeps the function alive for the whole call.
        const pybind11::handle f = progress;
        return [f](std::uint64_t done, std::uint64_t total) {
            pybind11::gil_scoped_acquire gil;
            f(done, total);
        };
    }

    ScopedProgress scope_;
};

}  // namespace avsplat::python
