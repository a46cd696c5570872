// Private: a writer's two stages overlapped. The calling thread fills chunk k + 1 (usually with
// an OpenMP loop) while a second thread hands chunk k to the sink (a write() that copies into the
// page cache or waits for the disk), two buffers in turn. The sink sees the chunks in order, so
// the bytes written are those of the serial loop.
//
// Progress (core/progress.h): chunks, reported by the calling thread before each fill.
// Errors: an exception from `fill` or `sink` (or the progress callback) stops both stages (so does the caller's interrupt
// check, polled before each chunk: Interrupted); the first one is rethrown on the
// calling thread after the second thread has finished, and no chunk after the failing one reaches
// the sink.
#pragma once

#include "core/interrupt_poll.h"
#include "core/progress_report.h"

#include <condition_variable>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace avsplat::detail {

/// Calls fill(k, buffer) -> bytes for k = 0 .. chunks - 1 on this thread and sink(buffer, bytes)
/// on a second one, in order, with two buffers of `capacity` bytes. fill must not write more
/// than `capacity` bytes. With one chunk nothing is overlapped and no thread is started.
template <class Fill, class Sink>
void pipeline_chunks(std::size_t chunks, std::size_t capacity, Fill&& fill, Sink&& sink) {
    if (chunks == 0) return;
    if (chunks == 1) {
        std::vector<char> buffer(capacity);
        sink(buffer.data(), fill(std::size_t(0), buffer.data()));
        return;
    }
    InterruptPoll poll;
    ProgressReport report(chunks);  // chunks written
    std::vector<char> buffers[2] = {std::vector<char>(capacity), std::vector<char>(capacity)};
    std::size_t bytes[2] = {0, 0};
    bool full[2] = {false, false};
    bool stop = false;  // set by either side on an error
    std::exception_ptr error;
    std::mutex mutex;
    std::condition_variable changed;
    // Records the first error and stops both sides.
    auto fail = [&](std::exception_ptr e) {
        std::lock_guard<std::mutex> lock(mutex);
        if (!error) error = e;
        stop = true;
        changed.notify_all();
    };

    std::thread writer([&] {
        for (std::size_t k = 0; k < chunks; ++k) {
            const int b = int(k % 2);
            {
                std::unique_lock<std::mutex> lock(mutex);
                changed.wait(lock, [&] { return full[b] || stop; });
                if (!full[b]) return;  // stopped, and this chunk will never come
            }
            try {
                sink(static_cast<const char*>(buffers[b].data()), bytes[b]);
            } catch (...) {
                fail(std::current_exception());
                return;
            }
            std::lock_guard<std::mutex> lock(mutex);
            full[b] = false;
            changed.notify_all();
        }
    });

    for (std::size_t k = 0; k < chunks; ++k) {
        const int b = int(k % 2);
        {
            std::unique_lock<std::mutex> lock(mutex);
            changed.wait(lock, [&] { return !full[b] || stop; });
            if (stop) break;
        }
        std::size_t n = 0;
        try {
            // The sink's thread has no interrupt check (it is per thread): poll here.
            if (poll.stop()) throw Interrupted();
            report.set(k);  // chunks filled so far
            n = fill(k, buffers[b].data());
        } catch (...) {
            fail(std::current_exception());
            break;
        }
        std::lock_guard<std::mutex> lock(mutex);
        bytes[b] = n;
        full[b] = true;
        changed.notify_all();
    }
    writer.join();
    if (error) std::rethrow_exception(error);
    report.finish();
}

}  // namespace avsplat::detail
