// Progress of a long subcommand: a redrawn bar on a terminal, plain lines otherwise.
//
// On a terminal (stderr is a tty) the bar is redrawn in place on stderr, at most every 0.1 s,
// and erased when the work finishes or fails, so that it never mixes with the one-line error
// message. When stderr is not a terminal (a log file, a test's pipe) progress is written as
// plain lines on stdout, one each time a tenth of the work is done, so that stderr carries only
// errors.
#pragma once

#include <chrono>
#include <cstddef>
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

    /// Marks `steps` more steps as done; `detail` (e.g. the file just read) is shown beside it.
    void advance(std::size_t steps = 1, const std::string& detail = {});
    /// Prints `line` on stdout without mixing it into the bar (erased first, then redrawn).
    void print(const std::string& line);
    /// Marks all steps as done and, on a terminal, erases the bar.
    void finish();

private:
    void draw(bool force);
    void erase();

    std::string label_;
    std::string detail_;
    std::size_t total_;
    std::size_t done_ = 0;
    std::size_t last_tenth_ = 0;
    bool terminal_;
    bool drawn_ = false;
    bool finished_ = false;
    std::chrono::steady_clock::time_point start_;
    std::chrono::steady_clock::time_point last_draw_;
};

}  // namespace avsplat::cli
