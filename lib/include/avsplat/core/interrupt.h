// Interrupting long calls (fusion, rendering, point maps, writers): a check that the caller installs, and
// the exception a call throws when the check says stop.
//
// Long loops poll the check of the thread that made the call, from that thread only, at most
// every 0.1 s by default (a call shorter than that never runs it); when it returns true, every worker thread skips the rest of its work,
// the parallel region ends normally (no exception crosses OpenMP), and the call throws
// avsplat::Interrupted. Nothing the call would have returned is kept. Without an installed check
// a call is never interrupted. The Python bindings install one that runs Python's signal
// handlers, so Ctrl-C raises KeyboardInterrupt within about a second; the command-line tool
// installs one that sees SIGINT and SIGTERM.
#pragma once

#include <chrono>
#include <functional>
#include <stdexcept>

namespace avsplat {

/// Thrown by a call that stopped because its interrupt check returned true.
class Interrupted : public std::runtime_error {
public:
    Interrupted() : std::runtime_error("interrupted") {}
};

/// An interrupt check and how often it runs.
struct InterruptCheck {
    std::function<bool()> check;
    /// A loop runs the check when at least this long has passed since the loop started or
    /// since the last run (0: at every poll, for checks as cheap as reading a flag).
    std::chrono::nanoseconds interval{std::chrono::milliseconds(100)};
};

/// Installs `check` for calls made on this thread while the object lives (the previous check
/// comes back afterwards). `check` runs on this thread, between chunks of work, at most every
/// `interval`; it returns true to stop the call. It must not throw (an exception counts as true).
class ScopedInterruptCheck {
public:
    explicit ScopedInterruptCheck(std::function<bool()> check,
                                  std::chrono::nanoseconds interval = std::chrono::milliseconds(100));
    ~ScopedInterruptCheck();
    ScopedInterruptCheck(const ScopedInterruptCheck&) = delete;
    ScopedInterruptCheck& operator=(const ScopedInterruptCheck&) = delete;

private:
    InterruptCheck installed_;
    const InterruptCheck* previous_;
};

/// Runs this thread's installed check now and throws Interrupted when it returns true (for
/// serial steps between parallel ones, e.g. before a writer renames its file into place).
void throw_if_interrupted();

}  // namespace avsplat
