// Progress of a long subcommand: a bar redrawn in place on stderr when stderr is a terminal,
// nothing otherwise (a log file, a pipe, a test) or with the global --quiet.
//
// The bar is redrawn at most every 0.1 s and erased when the work finishes or fails, so that it
// never mixes with the one-line error message or with the results on stdout. A Progress can
// follow a library call through the call's progress callback (avsplat/core/progress.h):
// `follow()` installs one for the calls made while its return value lives.
#pragma once

#include "avsplat/core/progress.h"

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>

namespace avsplat::cli {

class Progress {
public:
    /// `label` says what is counted ("reading inputs"); `total` > 0 steps.
    Progress(std::string label, std::size_t total);
    /// Erases the bar (also when the work ended with an exception).
    ~Progress();
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    /// Set by the global --quiet: no bar for the rest of the run.
    static void set_quiet(bool quiet);
    /// True when bars are drawn (stderr is a terminal and --quiet was not given).
    static bool shown();

    /// Marks `steps` more steps as done; `detail` (e.g. the file just read) is shown beside it.
    void advance(std::size_t steps = 1, const std::string& detail = {});
    /// Sets the steps done and the total (for a library call's own units).
    void set(std::size_t done, std::size_t total);
    /// Prints `line` on stdout without mixing it into the bar (erased first, then redrawn).
    void print(const std::string& line);
    /// Marks all steps as done and erases the bar.
    void finish();
    /// Shows the progress of the library calls made while the returned object lives.
    std::unique_ptr<ScopedProgress> follow();

private:
    void draw(bool force);
    void erase();

    std::string label_;
    std::string detail_;
    std::size_t total_;
    std::size_t done_ = 0;
    bool terminal_;
    bool drawn_ = false;
    bool finished_ = false;
    std::chrono::steady_clock::time_point start_;
    std::chrono::steady_clock::time_point last_draw_;
};

}  // namespace avsplat::cli
