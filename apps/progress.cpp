#include "progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace avsplat::cli {

namespace {
bool quiet = false;
}  // namespace

void Progress::set_quiet(bool q) { quiet = q; }

bool Progress::shown() { return !quiet && isatty(STDERR_FILENO) == 1; }

Progress::Progress(std::string label, std::size_t total)
    : label_(std::move(label)), total_(std::max<std::size_t>(total, 1)), terminal_(shown()),
      start_(std::chrono::steady_clock::now()), last_draw_(start_) {
    draw(true);
}

Progress::~Progress() { erase(); }

void Progress::advance(std::size_t steps, const std::string& detail) {
    done_ = std::min(total_, done_ + steps);
    detail_ = detail;
    draw(done_ == total_);
}

void Progress::set(std::size_t done, std::size_t total) {
    total_ = std::max<std::size_t>(total, 1);
    done_ = std::min(total_, done);
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
    erase();
    finished_ = true;
}

std::unique_ptr<ScopedProgress> Progress::follow() {
    if (!terminal_) return std::make_unique<ScopedProgress>(ProgressCallback{});
    return std::make_unique<ScopedProgress>(
        [this](std::uint64_t done, std::uint64_t total) { set(std::size_t(done), std::size_t(total)); });
}

void Progress::draw(bool force) {
    if (!terminal_ || finished_) return;
    const auto now = std::chrono::steady_clock::now();
    if (!force && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    const double elapsed = std::chrono::duration<double>(now - start_).count();
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
