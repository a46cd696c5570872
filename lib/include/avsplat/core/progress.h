// Progress of long calls (fusion, simplification, pruning, rendering of many cameras): a callback
// the caller installs for the calls it makes on one thread, as for the interrupt check
// (avsplat/core/interrupt.h).
//
// A long call reports (done, total) in units it documents (samples, Gaussians, cameras), on
// the thread that made it (never on a worker thread), between chunks of its work. The points
// are fixed by the input alone, so the sequence of reports is the same for every thread
// count, and the result is the same with or without a callback. The first report is (0, total),
// `done` never decreases, and a call that succeeds ends with (total, total). The callback may
// throw: the exception stops the call (the rest of its work is skipped, nothing is returned)
// and propagates from it. Only the outermost reporting call reports: calls it makes (the
// renders inside a pruning) see no callback. Without an installed callback reporting costs a
// branch per chunk.
#pragma once

#include <cstdint>
#include <functional>

namespace avsplat {

/// Called with (work done, total work) of the running call.
using ProgressCallback = std::function<void(std::uint64_t done, std::uint64_t total)>;

/// Installs `callback` for the long calls made on this thread while the object lives (the
/// previous one comes back afterwards); an empty callback installs none.
class ScopedProgress {
public:
    explicit ScopedProgress(ProgressCallback callback);
    ~ScopedProgress();
    ScopedProgress(const ScopedProgress&) = delete;
    ScopedProgress& operator=(const ScopedProgress&) = delete;

private:
    ProgressCallback installed_;
    const ProgressCallback* previous_;
};

}  // namespace avsplat
