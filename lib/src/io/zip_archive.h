// Private: zip containers (.npz, SOG) read and written through Debian's libzip. Only what the
// formats need: stored and deflate entries, whole-entry reads with a hard output bound, and an
// atomic writer. libzip parses the container (end records, zip64, the central directory, local
// headers); this layer turns every failure into an avsplat::IOError that starts with the file
// name (or the caller's `what`) and names the entry.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace avsplat::io {

struct ZipEntryInfo {
    std::string name;                 // as stored (no character set conversion)
    std::uint64_t size = 0;           // uncompressed size the central directory declares
    std::uint64_t compressed_size = 0;
};

/// A read-only zip archive. Errors are avsplat::IOError whose message starts with `what`
/// (the path for open_file). Not safe for concurrent calls on one object; separate objects
/// are independent.
class ZipReader {
public:
    /// Opens the archive at `path`. The path is checked with io::regular_file_size first (a
    /// directory, FIFO or device is an IOError, never a hang); files shorter than a zip end
    /// record (22 bytes), files without one, multi-disk and inconsistent archives are IOErrors.
    static ZipReader open_file(const std::string& path);
    /// Opens an archive held in memory; `data` must outlive the reader (it is not copied).
    static ZipReader open_memory(const void* data, std::size_t size, std::string what);

    ZipReader(ZipReader&&) noexcept;
    ZipReader& operator=(ZipReader&&) noexcept;
    ~ZipReader();

    /// The `what` given to open (the path for open_file).
    const std::string& what() const;
    /// Every entry, in the central directory's order (duplicate names included).
    const std::vector<ZipEntryInfo>& entries() const;
    /// The first entry named `name` (hash lookup), or nullptr when there is none.
    const ZipEntryInfo* find(const std::string& name) const;
    /// Index of `entry` (a pointer from entries() or find()) in entries().
    std::size_t index_of(const ZipEntryInfo& entry) const;

    /// Inflates entry `index` (< entries().size(), else std::out_of_range) and checks its
    /// CRC-32. Memory is bounded by min(declared size, max_bytes): an entry that declares more
    /// than max_bytes is refused before any inflation, and inflation stops with an IOError as
    /// soon as the output would exceed the declared size (a zip or deflate bomb). Encrypted
    /// entries and methods other than stored (0) and deflate (8) are IOErrors, as are sizes
    /// that no deflate stream can have (more than 1032:1) and stored entries whose two sizes
    /// differ. Messages read "<what>: entry '<name>': <reason>".
    std::vector<unsigned char> read(std::size_t index, std::uint64_t max_bytes) const;

    /// The first min(n, declared size) bytes of entry `index`, inflating no more than that (for
    /// reading a format's header before deciding how much the entry may hold). Same checks as
    /// read(), except the CRC, which needs the whole entry.
    std::vector<unsigned char> read_prefix(std::size_t index, std::size_t n) const;

    /// Inflates entry `index` through a fixed 64 KiB buffer, keeping nothing, with read()'s
    /// checks (length, CRC-32). For telling corrupt data apart from a format error found in a
    /// prefix: a header that fails to parse is reported as the CRC error it may really be.
    void verify(std::size_t index) const;

private:
    struct Impl;
    explicit ZipReader(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

struct ZipWriteEntry {
    std::string name;
    const unsigned char* data = nullptr;  // borrowed for the duration of write_zip
    std::size_t size = 0;
    bool deflate = false;                 // deflate (zlib's default level) or stored
};

/// Writes a zip archive of `entries`, in order, through AtomicFile (the destination is either
/// the complete archive or untouched). Entry times are the DOS epoch (1980-01-01 00:00), so
/// equal inputs give byte-identical files; zip64 records are written where sizes or counts need
/// them. Throws std::invalid_argument for an empty or duplicate name or null data with a
/// non-zero size, and IOError naming `path` when writing fails.
void write_zip(const std::string& path, const std::vector<ZipWriteEntry>& entries);

}  // namespace avsplat::io
