#include "progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace avsplat::cli {

Progress::Progress(std::string label, std::size_t total)
    : label_(std::move(label)), total_(std::max<std::size_t>(total, 1)),
      terminal_(isatty(STDERR_FILENO) == 1), start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {
    draw(true);
}

Progress::~Progress() { erase(); }

void Progress::advance(std::size_t steps, const std::string& detail) {
    done_ = std::min(total_, done_ + steps);
    detail_ = detail;
    draw(done_ == total_);
}

void Progress::print(const std::string& line) {
    const bool redraw = drawn_;
    erase();
    std::printf("%s\n", line.c_str());
    std::fflush(stdout);
    if (redraw) draw(true);
}

void Progress::finish() {
    if (finished_) return;
    done_ = total_;
    draw(true);
    erase();
    finished_ = true;
}

void Progress::draw(bool force) {
    const auto now = std::chrono::steady_clock::now();
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    if (!terminal_) {
        // One line per tenth of the work (and the last step), never the same tenth twice.
        const std::size_t tenth = done_ * 10 / total_;
        if (done_ == 0 || (tenth == last_tenth_ && done_ != total_) || finished_) return;
        if (done_ == total_ && last_tenth_ == 10) return;
        last_tenth_ = tenth;
        std::printf("%s: %zu/%zu%s%s (%.1f s)\n", label_.c_str(), done_, total_,
                    detail_.empty() ? "" : " ", detail_.c_str(), elapsed);
        std::fflush(stdout);
        return;
    }
    if (!force && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(kWidth * done_ / total_);
    std::string bar(static_cast<std::size_t>(filled), '#');
    bar.append(static_cast<std::size_t>(kWidth - filled), '.');
    std::string detail = detail_;
    if (detail.size() > 40) detail = "..." + detail.substr(detail.size() - 37);
    std::fprintf(stderr, "\r\033[K%s [%s] %zu/%zu %.1f s %s", label_.c_str(), bar.c_str(), done_,
                 total_, elapsed, detail.c_str());
    std::fflush(stderr);
    drawn_ = true;
}

void Progress::erase() {
    if (terminal_ && drawn_) {
        std::fprintf(stderr, "\r\033[K");
        std::fflush(stderr);
        drawn_ = false;
    }
}

}  // namespace avsplat::cli
