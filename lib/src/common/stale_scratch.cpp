// Scratch files and folders of killed processes (common/stale_scratch.h).
#include "common/stale_scratch.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <system_error>

namespace avsplat::detail {

namespace {

// Whether process `pid` is gone (kill(pid, 0) says there is no such process).
bool process_gone(long pid) { return pid > 0 && ::kill(pid_t(pid), 0) != 0 && errno == ESRCH; }

}  // namespace

void remove_stale_scratch(const std::string& folder, const std::string& prefix, bool folders) {
    DIR* dir = ::opendir(folder.c_str());
    if (!dir) return;
    while (const dirent* e = ::readdir(dir)) {
        const std::string name = e->d_name;
        if (name.compare(0, prefix.size(), prefix) != 0) continue;
        // prefix, then the owner's PID, '-', and mkstemp's or mkdtemp's six characters.
        char* end = nullptr;
        const long pid = std::strtol(name.c_str() + prefix.size(), &end, 10);
        if (end == name.c_str() + prefix.size() || *end != '-' || std::strlen(end + 1) != 6) continue;
        if (!process_gone(pid)) continue;
        const std::string path = folder + "/" + name;
        // The owner holds an exclusive lock for its life (on the file, or the folder's lock
        // file): a free lock confirms it is gone, also when PIDs come from another namespace.
        const int fd = ::open((folders ? path + "/.lock" : path).c_str(), O_RDONLY | O_NOFOLLOW | O_CLOEXEC);
        if (fd < 0) continue;
        const bool free = ::flock(fd, LOCK_EX | LOCK_NB) == 0;
        if (free) {
            if (folders) {
                std::error_code ec;
                std::filesystem::remove_all(path, ec);
            } else {
                ::unlink(path.c_str());
            }
        }
        ::close(fd);
    }
    ::closedir(dir);
}

int lock_scratch(int fd) { return ::flock(fd, LOCK_EX | LOCK_NB); }

}  // namespace avsplat::detail
