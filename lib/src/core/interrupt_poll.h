// InterruptPoll: how a parallel loop notices the interrupt check of its caller
// (avsplat/core/interrupt.h) without an exception crossing OpenMP.
//
//   InterruptPoll poll;                     // on the calling thread, before the region
//   #pragma omp parallel for ...
//   for (i ...) { if (poll.stop(i)) continue; ... }
//   poll.throw_if_stopped();                // after the region: throws Interrupted
//
// It also carries exceptions out of a region, which OpenMP does not (an exception leaving a
// region calls std::terminate): code that may throw inside the region (allocations: std::bad_alloc)
// runs in poll.guard([&] { ... }); the first exception is kept, stops the other threads like an
// interrupt, and throw_if_stopped() rethrows it after the region. Every thread must still reach
// each barrier and worksharing construct: guard one stretch of work at a time, never a barrier.
//
// stop(i) is one relaxed atomic load on most iterations; every 256th iteration, on the calling
// thread, and at most every InterruptCheck::interval, it runs the check. Once the check said stop, every thread's
// stop() returns true, so the remaining iterations are skipped.
#pragma once

#include "avsplat/core/interrupt.h"
#include "common/stop_check.h"

#include <atomic>
#include <chrono>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>

namespace avsplat {

namespace detail {
extern thread_local const InterruptCheck* current_interrupt_check;
}  // namespace detail

class InterruptPoll : public StopCheck {
public:
    InterruptPoll() noexcept
        : check_(detail::current_interrupt_check), owner_(std::this_thread::get_id()),
          last_(std::chrono::steady_clock::now()) {}

    /// True when the call should stop; `i` is the loop index (the check runs when i % 256 == 0).
    bool stop(std::int64_t i = 0) noexcept {
        if (stopped_.load(std::memory_order_relaxed)) return true;
        if (check_ == nullptr || (i & 255) != 0) return false;
        return poll();
    }

    bool stopped() const noexcept { return stopped_.load(std::memory_order_relaxed); }

    /// StopCheck: stop() for kernels of `common` (the radix sort) that know no InterruptPoll.
    bool should_stop() noexcept override { return stop(); }

    /// Runs f(); an exception from it is kept (the first one) and stops the loop.
    template <class F>
    void guard(F&& f) noexcept {
        try {
            f();
        } catch (...) {
            const std::lock_guard<std::mutex> lock(mutex_);
            if (!error_) error_ = std::current_exception();
            stopped_.store(true, std::memory_order_relaxed);
        }
    }

    /// After the region: rethrows the kept exception, or throws Interrupted when the check said
    /// stop.
    void throw_if_stopped() {
        if (error_) std::rethrow_exception(error_);
        // The calling thread may have run no iteration that polled (on a loaded machine the
        // other threads can take them all): it looks once more here, at the same rate limit.
        if (!stopped() && check_ != nullptr) poll();
        if (stopped()) throw Interrupted();
    }

    /// Runs a check; an exception from it counts as "stop".
    static bool run(const std::function<bool()>& check) noexcept {
        try {
            return check();
        } catch (...) {
            return true;
        }
    }

private:
    bool poll() noexcept {
        if (std::this_thread::get_id() != owner_) return false;
        const auto now = std::chrono::steady_clock::now();
        if (now - last_ < check_->interval) return false;
        last_ = now;
        if (run(check_->check)) stopped_.store(true, std::memory_order_relaxed);
        return stopped();
    }

    const InterruptCheck* check_;
    std::thread::id owner_;
    std::chrono::steady_clock::time_point last_;
    std::atomic<bool> stopped_{false};
    std::mutex mutex_;
    std::exception_ptr error_;
};

}  // namespace avsplat
