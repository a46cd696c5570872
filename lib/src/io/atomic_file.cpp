#include "avsplat/io/atomic_file.h"

#include "avsplat/core/interrupt.h"
#include "core/interrupt_poll.h"
#include "common/stale_scratch.h"

#include "avsplat/core/error.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace avsplat {

namespace {

std::string folder_of(const std::string& path) {
    const std::size_t slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

std::string name_of(const std::string& path) {
    const std::size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

// The file a write to `path` must replace: the final target when `path` is a symbolic link
// (so the link survives), else `path` itself.
std::string resolve_target(const std::string& path) {
    struct stat st;
    if (::lstat(path.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return path;
    std::string target = path;
    for (int hops = 0; hops < 40; ++hops) {
        std::vector<char> buf(PATH_MAX + 1);
        const ssize_t n = ::readlink(target.c_str(), buf.data(), PATH_MAX);
        if (n < 0) break;  // not a link any more: target is final
        std::string next(buf.data(), std::size_t(n));
        if (next.empty() || next[0] != '/') next = folder_of(target) + "/" + next;
        target = next;
        if (::lstat(target.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) break;
    }
    return target;
}

}  // namespace

AtomicFile::AtomicFile(const std::string& path) : path_(path) {
    if (path.empty()) throw OutputError("empty output path");
    if (path.find('\0') != std::string::npos)
        throw OutputError(std::string(path.c_str()) + "...: output path contains a NUL byte");
    target_ = resolve_target(path);
    struct stat st;
    if (::stat(target_.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
        if (S_ISDIR(st.st_mode)) throw OutputError(path + ": is a directory");
        // A device or a pipe: renaming over it would replace it, so write in place. O_NONBLOCK
        // keeps a FIFO with no reader from blocking the open forever.
        const int fd = ::open(target_.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
        if (fd < 0) fail("cannot open for writing", errno);
        ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
        file_ = ::fdopen(fd, "wb");
        if (!file_) {
            const int err = errno;
            ::close(fd);
            fail("cannot open for writing", err);
        }
        return;
    }
    // ".NAME.avsplat-PID-XXXXXX", locked while this process lives: the temporary files of a
    // process that was killed (SIGKILL, a power cut) are removed by the next write to NAME.
    const std::string prefix = "." + name_of(target_) + ".avsplat-";
    detail::remove_stale_scratch(folder_of(target_), prefix, false);
    std::string templ = folder_of(target_) + "/" + prefix + std::to_string(::getpid()) + "-XXXXXX";
    std::vector<char> buf(templ.begin(), templ.end());
    buf.push_back('\0');
    const int fd = ::mkostemp(buf.data(), O_CLOEXEC);
    if (fd < 0) fail("cannot open for writing (creating a file in " + folder_of(target_) + ")", errno);
    detail::lock_scratch(fd);
    temp_.assign(buf.data());
    file_ = ::fdopen(fd, "wb");
    if (!file_) {
        const int err = errno;
        ::close(fd);
        ::unlink(temp_.c_str());
        temp_.clear();
        fail("cannot open for writing", err);
    }
}

AtomicFile::~AtomicFile() {
    if (file_) std::fclose(file_);
    if (!committed_ && !temp_.empty()) ::unlink(temp_.c_str());
}

void AtomicFile::fail(const std::string& what, int err) {
    throw OutputError(path_ + ": " + what + (err ? std::string(": ") + std::strerror(err) : ""));
}

void AtomicFile::write(const void* data, std::size_t n) {
    if (!file_ || committed_) throw OutputError(path_ + ": write after commit");
    if (n && std::fwrite(data, 1, n, file_) != n) fail("write failed", errno);
    written_ += n;
    // A writer producing a large file polls here (Ctrl-C within about a second), at the check's
    // own rate: it can be costly (Python takes its lock to run the signal handlers).
    if (const InterruptCheck* check = detail::current_interrupt_check) {
        const auto now = std::chrono::steady_clock::now();
        if (now - last_poll_ >= check->interval) {
            last_poll_ = now;
            if (InterruptPoll::run(check->check)) throw Interrupted();
        }
    }
#ifdef __linux__
    // commit() syncs the temporary file before renaming it. For a large file, start the disk
    // write-back of every 32 MiB as it is written, so that it runs while the rest is produced and
    // commit's fsync only waits for the tail. A hint: its errors are fsync's to report.
    constexpr std::uint64_t kWriteBackStep = std::uint64_t(32) << 20;
    if (!temp_.empty() && written_ - flushed_ >= kWriteBackStep && std::fflush(file_) == 0) {
        ::sync_file_range(::fileno(file_), off64_t(flushed_), off64_t(written_ - flushed_), SYNC_FILE_RANGE_WRITE);
        flushed_ = written_;
    }
#endif
}

void AtomicFile::commit() {
    if (!file_ || committed_) throw OutputError(path_ + ": commit called twice");
    // An interrupted call (Ctrl-C) leaves the destination as it was: the destructor removes the
    // temporary file.
    throw_if_interrupted();
    std::FILE* f = file_;
    file_ = nullptr;
    int err = 0;
    if (std::fflush(f) != 0) err = errno;
    if (!err && !temp_.empty() && ::fsync(::fileno(f)) != 0) err = errno;
    if (!err && !temp_.empty()) {
        // mkostemp made the file 0600; give it what a plain create would (or the old file's).
        struct stat st;
        mode_t mode;
        if (::stat(target_.c_str(), &st) == 0) {
            mode = st.st_mode & 07777;
        } else {
            const mode_t mask = ::umask(0);
            ::umask(mask);
            mode = 0666 & ~mask;
        }
        if (::fchmod(::fileno(f), mode) != 0) err = errno;
    }
    if (std::fclose(f) != 0 && !err) err = errno;
    if (err) fail("write failed", err);
    if (!temp_.empty() && ::rename(temp_.c_str(), target_.c_str()) != 0)
        fail("cannot replace the file", errno);
    committed_ = true;
}

void write_file_atomically(const std::string& path, const std::string& bytes) {
    AtomicFile file(path);
    file.write(bytes);
    file.commit();
}

}  // namespace avsplat
