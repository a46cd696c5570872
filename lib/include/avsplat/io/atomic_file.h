// AtomicFile: writes a file so that the destination is either the complete new file or left as
// it was. Every avsplat writer goes through it.
//
// The bytes go to a temporary file in the destination's folder (".NAME.avsplat-PID-XXXXXX", locked
// with flock while the writing process lives, so that the next AtomicFile for NAME removes those
// of a process that was killed); commit()
// flushes it to disk (fsync), gives it the permissions a new file would get (0666 & ~umask, or
// the existing file's), and renames it over the destination. If anything fails (a full disk, a
// file-size limit, a read-only or missing folder) an avsplat::IOError names the destination and
// the reason, the temporary file is removed and the destination is untouched; a process killed
// mid-write leaves the destination untouched too (and at most the temporary file behind).
// A destination that is a symbolic link keeps the link: its target is replaced. A destination
// that exists and is not a regular file (/dev/null, /dev/full, a FIFO) is written in place,
// because renaming over it would replace the device or pipe; errors are still reported.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

namespace avsplat {

class AtomicFile {
public:
    /// Creates the temporary file. Throws IOError naming `path` when it cannot (no such folder,
    /// no permission, a path containing a NUL byte).
    explicit AtomicFile(const std::string& path);
    /// Removes the temporary file unless commit() succeeded.
    ~AtomicFile();
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;

    /// Appends n bytes. Throws IOError ("<path>: write failed: No space left on device"), and
    /// Interrupted when the caller's interrupt check says stop (run at most every its interval).
    void write(const void* data, std::size_t n);
    void write(const std::string& bytes) { write(bytes.data(), bytes.size()); }

    /// Flushes, syncs and renames over the destination. Throws IOError on failure, and
    /// Interrupted when the caller's interrupt check (avsplat/core/interrupt.h) says stop; the
    /// destination is then untouched. Call once, after the last write.
    void commit();

    /// The destination path, as given.
    const std::string& path() const noexcept { return path_; }

private:
    [[noreturn]] void fail(const std::string& what, int err);

    std::string path_;       // as given, for messages
    std::string target_;     // what is replaced: path_, or the target of a symbolic link
    std::string temp_;       // the temporary file; empty when writing in place
    std::FILE* file_ = nullptr;
    bool committed_ = false;
    std::uint64_t written_ = 0;  // bytes written so far
    std::uint64_t flushed_ = 0;  // bytes whose write-back to the disk has been started
    std::chrono::steady_clock::time_point last_poll_ = std::chrono::steady_clock::now();
};

/// Writes `bytes` to `path` through an AtomicFile.
void write_file_atomically(const std::string& path, const std::string& bytes);

}  // namespace avsplat
