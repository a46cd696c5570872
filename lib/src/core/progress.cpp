#include "avsplat/core/progress.h"

#include "core/progress_report.h"

namespace avsplat {

namespace {
thread_local const ProgressCallback* current_progress = nullptr;
}  // namespace

namespace detail {
const ProgressCallback* installed_progress() noexcept { return current_progress; }
void install_progress(const ProgressCallback* callback) noexcept { current_progress = callback; }
}  // namespace detail

ScopedProgress::ScopedProgress(ProgressCallback callback)
    : installed_(std::move(callback)), previous_(detail::installed_progress()) {
    detail::install_progress(installed_ ? &installed_ : nullptr);
}

ScopedProgress::~ScopedProgress() { detail::install_progress(previous_); }

}  // namespace avsplat
