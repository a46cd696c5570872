#include "avsplat/core/progress.h"

#include "core/progress_report.h"

namespace avsplat {

namespace detail {
thread_local const ProgressCallback* current_progress = nullptr;
}  // namespace detail

ScopedProgress::ScopedProgress(ProgressCallback callback)
    : installed_(std::move(callback)), previous_(detail::current_progress) {
    detail::current_progress = installed_ ? &installed_ : nullptr;
}

ScopedProgress::~ScopedProgress() { detail::current_progress = previous_; }

}  // namespace avsplat
