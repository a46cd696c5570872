// Open3D's log lines inside the avsplat tool. Open3D prints its warnings ("Write PCD failed:
// unable to open file.") to stdout with terminal colour codes, which breaks the tool's rule that
// stdout carries only results and an error is one line on stderr. Open3DLog captures them for the
// duration of an Open3D call: a failure folds them into its one-line error, a success passes them
// on to stderr as warnings.
#pragma once

#include <open3d/utility/Logging.h>

#include <cstdio>
#include <string>
#include <vector>

namespace avsplat::cli {

class Open3DLog {
public:
    Open3DLog() {
        open3d::utility::Logger::GetInstance().SetPrintFunction(
            [this](const std::string& line) { lines_.push_back(plain(line)); });
    }
    ~Open3DLog() { open3d::utility::Logger::GetInstance().ResetPrintFunction(); }
    Open3DLog(const Open3DLog&) = delete;
    Open3DLog& operator=(const Open3DLog&) = delete;

    /// The captured lines joined by "; " ("" when there are none).
    std::string text() const {
        std::string out;
        for (const std::string& l : lines_) out += (out.empty() ? "" : "; ") + l;
        return out;
    }
    /// " (<text>)", or "" when nothing was logged: for appending to an error message.
    std::string reason() const { return lines_.empty() ? std::string() : " (" + text() + ")"; }
    /// Writes the captured lines to stderr, one "avsplat: warning: ..." line each.
    void flush_to_stderr() {
        for (const std::string& l : lines_) std::fprintf(stderr, "avsplat: warning: %s\n", l.c_str());
        lines_.clear();
    }

private:
    // Without ANSI escape sequences (ESC '[' ... final letter), trailing newlines and Open3D's
    // "[Open3D WARNING] " style tag.
    static std::string plain(const std::string& s) {
        std::string out;
        for (std::size_t i = 0; i < s.size(); ++i) {
            if (s[i] == '\x1b' && i + 1 < s.size() && s[i + 1] == '[') {
                i += 2;
                while (i < s.size() && !((s[i] >= 'A' && s[i] <= 'Z') || (s[i] >= 'a' && s[i] <= 'z'))) ++i;
                continue;
            }
            out += s[i];
        }
        while (!out.empty() && (out.back() == '\n' || out.back() == '\r' || out.back() == ' ')) out.pop_back();
        if (out.compare(0, 8, "[Open3D ") == 0) {
            const std::size_t close = out.find("] ");
            if (close != std::string::npos) out = "Open3D: " + out.substr(close + 2);
        }
        return out;
    }

    std::vector<std::string> lines_;
};

}  // namespace avsplat::cli
