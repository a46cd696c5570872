// ProgressReport: how a long call reports to the callback of avsplat/core/progress.h.
//
//   ProgressReport report(total);          // on the calling thread: reports (0, total)
//   for (chunk ...) { <parallel work>; report.advance(chunk size); }
//   report.finish();                       // (total, total), once
//
// While it lives the thread's callback is hidden, so that the calls it makes report nothing.
// Report only from the calling thread: outside parallel regions, or inside one from the master
// thread through InterruptPoll::guard (which carries the callback's exception out of the region
// and stops the other threads). An exception from the callback propagates from advance(), set()
// and finish().
#pragma once

#include "avsplat/core/progress.h"

#include <algorithm>
#include <cstdint>

namespace avsplat {

/// How many equal runs a parallel loop that reports is cut into (a fixed number, so that the
/// reports do not depend on the thread count).
constexpr std::int64_t kProgressSlices = 64;

namespace detail {
// The calling thread's installed callback (nullptr: none). Functions rather than an extern
// thread_local, whose access from inlined code UBSan reports as a null load under GCC 12.
const ProgressCallback* installed_progress() noexcept;
void install_progress(const ProgressCallback* callback) noexcept;
}  // namespace detail

class ProgressReport {
public:
    explicit ProgressReport(std::uint64_t total)
        : callback_(detail::installed_progress()), total_(total) {
        detail::install_progress(nullptr);
        try {
            report();
        } catch (...) {  // no destructor runs for a constructor that throws
            detail::install_progress(callback_);
            throw;
        }
    }
    ~ProgressReport() { detail::install_progress(callback_); }
    ProgressReport(const ProgressReport&) = delete;
    ProgressReport& operator=(const ProgressReport&) = delete;

    /// True when a callback listens (to skip work done only to report).
    bool active() const noexcept { return callback_ != nullptr; }
    /// `steps` more units done (capped at total).
    void advance(std::uint64_t steps) {
        done_ = std::min(total_, done_ + steps);
        report();
    }
    /// `done` units done in all (capped at total; never below what was reported).
    void set(std::uint64_t done) {
        done_ = std::max(done_, std::min(total_, done));
        report();
    }
    /// Reports (total, total) unless it was the last report.
    void finish() {
        if (done_ == total_ && finished_) return;
        done_ = total_;
        report();
    }

private:
    void report() {
        if (done_ == total_) finished_ = true;
        if (callback_) (*callback_)(done_, total_);
    }

    const ProgressCallback* callback_;
    std::uint64_t total_;
    std::uint64_t done_ = 0;
    bool finished_ = false;
};

}  // namespace avsplat
