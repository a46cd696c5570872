// ReleaseGil: what every long binding uses in place of py::gil_scoped_release. Besides releasing
// the GIL it installs an interrupt check (avsplat/core/interrupt.h) that, on Python's main thread,
// takes the GIL back briefly and runs Python's signal handlers, so that Ctrl-C stops a long C++
// call within about a second. The call then throws avsplat::Interrupted, which module.cpp turns
// into the KeyboardInterrupt the handler raised. Other threads get no check: Python delivers
// signals to the main thread only.
//
// A call that reads GaussianClouds without the GIL names them (ReleaseGil release(cloud)): they are
// marked in use until it returns, and a method that would change a cloud's layout (add an extra
// channel, drop or add confidence) refuses with a RuntimeError while it is marked, instead of
// moving memory under the running call.
#pragma once

#include "avsplat/core/gaussians.h"
#include "avsplat/core/interrupt.h"

#include <pybind11/pybind11.h>

#include <cstddef>
#include <functional>
#include <initializer_list>
#include <mutex>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

namespace avsplat::python {

/// True on the thread Python runs its signal handlers on (call with the GIL held).
bool on_python_main_thread();

namespace detail {

struct CloudRegistry {
    std::mutex mutex;
    std::unordered_map<const GaussianCloud*, std::size_t> users;
};

inline CloudRegistry& cloud_registry() {
    static CloudRegistry r;
    return r;
}

}  // namespace detail

/// Throws std::logic_error (RuntimeError) when a call running without the GIL reads `cloud`.
inline void refuse_if_in_use(const GaussianCloud& cloud, const char* method) {
    auto& r = detail::cloud_registry();
    std::lock_guard<std::mutex> lock(r.mutex);
    if (r.users.count(&cloud))
        throw std::logic_error(std::string("GaussianCloud.") + method +
                               ": the cloud is in use by a call running on another thread; wait for it to "
                               "return, or change a copy");
}

/// Marks clouds in use for its lifetime.
class CloudsInUse {
public:
    CloudsInUse(std::initializer_list<const GaussianCloud*> clouds) : clouds_(clouds) {
        auto& r = detail::cloud_registry();
        std::lock_guard<std::mutex> lock(r.mutex);
        for (const GaussianCloud* c : clouds_) ++r.users[c];
    }
    ~CloudsInUse() {
        auto& r = detail::cloud_registry();
        std::lock_guard<std::mutex> lock(r.mutex);
        for (const GaussianCloud* c : clouds_)
            if (--r.users[c] == 0) r.users.erase(c);
    }
    CloudsInUse(const CloudsInUse&) = delete;
    CloudsInUse& operator=(const CloudsInUse&) = delete;

private:
    std::vector<const GaussianCloud*> clouds_;
};

class ReleaseGil {
public:
    ReleaseGil() : interrupt_(on_python_main_thread() ? check_signals : std::function<bool()>()) {}
    /// Releases the GIL and marks `clouds` in use until destroyed.
    template <class... Clouds>
    explicit ReleaseGil(const GaussianCloud& cloud, const Clouds&... more)
        : in_use_{&cloud, &more...},
          interrupt_(on_python_main_thread() ? check_signals : std::function<bool()>()) {}

private:
    static bool check_signals() {
        pybind11::gil_scoped_acquire gil;
        return PyErr_CheckSignals() != 0;
    }
    CloudsInUse in_use_{};             // marked first, unmarked last (with the GIL held)
    ScopedInterruptCheck interrupt_;   // installed first, removed last
    pybind11::gil_scoped_release release_;
};

}  // namespace avsplat::python
