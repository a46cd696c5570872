// Zip containers through libzip (io/zip_archive.h).
#include "io/zip_archive.h"

#include "avsplat/core/error.h"
#include "avsplat/io/atomic_file.h"
#include "io/input_file.h"

#include <zip.h>

#include <algorithm>
#include <functional>
#include <limits>
#include <new>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>
#include <utility>

namespace avsplat::io {

namespace {

// A zip end record is 22 bytes; nothing shorter can be an archive. (libzip opens an empty file
// as a new, empty archive, which a reader must not.)
constexpr std::uint64_t kMinArchiveSize = 22;
// Deflate expands by at most 1032:1; a directory claiming more is corrupt (and checking it keeps
// a forged size from sizing an allocation).
constexpr std::uint64_t kMaxDeflateRatio = 1040, kDeflateSlack = 1024;

// Why libzip failed, in words a user can act on. `code` is a ZIP_ER_* value.
std::string reason(int code, zip_error_t* error) {
    switch (code) {
        case ZIP_ER_NOZIP:
            return "not a zip archive: no zip end record or central directory (truncated or not a zip file)";
        case ZIP_ER_INCONS: return "inconsistent zip archive: headers out of range or disagreeing (corrupt archive)";
        case ZIP_ER_MULTIDISK: return "multi-disk zip archives are not supported";
        case ZIP_ER_CRC: return "CRC-32 mismatch (corrupt data)";
        case ZIP_ER_ZLIB:
        case ZIP_ER_COMPRESSED_DATA: return "corrupt deflate data (corrupt archive)";
        case ZIP_ER_EOF:
        case ZIP_ER_READ:
        case ZIP_ER_SEEK:
            return "data out of range of the file (truncated or corrupt archive)";
        case ZIP_ER_COMPNOTSUPP: return "compression method is not supported";
        case ZIP_ER_ENCRNOTSUPP:
        case ZIP_ER_NOPASSWD: return "encrypted entries are not supported";
        case ZIP_ER_MEMORY: throw std::bad_alloc();
        default: return error != nullptr ? zip_error_strerror(error) : "libzip error " + std::to_string(code);
    }
}

struct ErrorGuard {
    zip_error_t error;
    ErrorGuard() { zip_error_init(&error); }
    ~ErrorGuard() { zip_error_fini(&error); }
    ErrorGuard(const ErrorGuard&) = delete;
    ErrorGuard& operator=(const ErrorGuard&) = delete;
};

struct FileCloser {
    void operator()(zip_file_t* f) const { zip_fclose(f); }
};

}  // namespace

struct ZipReader::Impl {
    std::string what;
    zip_t* archive = nullptr;
    std::vector<ZipEntryInfo> entries;
    std::unordered_map<std::string, std::size_t> by_name;  // first entry of each name

    static std::unique_ptr<Impl> open(const std::function<zip_source_t*()>& make_source, std::string what);

    ~Impl() {
        if (archive != nullptr) zip_discard(archive);  // read-only: nothing to write back
    }

    [[noreturn]] void fail_entry(std::size_t index, const std::string& why) const {
        throw IOError(what + ": entry '" + entries[index].name + "': " + why);
    }

    // Checks entry `index` and opens it for reading; `limit` is the most output the caller takes.
    std::unique_ptr<zip_file_t, FileCloser> open_entry(std::size_t index, std::uint64_t limit) const {
        if (index >= entries.size())
            throw std::out_of_range("ZipReader::read: entry " + std::to_string(index) + " of " +
                                    std::to_string(entries.size()));
        zip_stat_t st;
        zip_stat_init(&st);
        if (zip_stat_index(archive, index, ZIP_FL_ENC_RAW, &st) != 0)
            fail_entry(index, reason(zip_error_code_zip(zip_get_error(archive)), zip_get_error(archive)));
        if ((st.valid & ZIP_STAT_ENCRYPTION_METHOD) && st.encryption_method != ZIP_EM_NONE)
            fail_entry(index, "encrypted entries are not supported");
        const int method = (st.valid & ZIP_STAT_COMP_METHOD) ? st.comp_method : -1;
        if (method != ZIP_CM_STORE && method != ZIP_CM_DEFLATE)
            fail_entry(index, "compression method " + std::to_string(method) +
                                  " is not supported (stored or deflate only)");
        const ZipEntryInfo& e = entries[index];
        const bool consistent = method == ZIP_CM_STORE
                                    ? e.size == e.compressed_size
                                    : e.compressed_size <= (std::numeric_limits<std::uint64_t>::max() - kDeflateSlack) / kMaxDeflateRatio &&
                                          e.size <= e.compressed_size * kMaxDeflateRatio + kDeflateSlack;
        if (!consistent) fail_entry(index, "sizes in the zip directory are inconsistent (corrupt archive)");
        if (std::min(e.size, limit) > std::numeric_limits<std::size_t>::max())
            fail_entry(index, "entry too large for this machine");
        zip_file_t* f = zip_fopen_index(archive, index, 0);
        if (f == nullptr) {
            zip_error_t* err = zip_get_error(archive);
            const int code = zip_error_code_zip(err);
            // libzip says "invalid argument" when the local header or the data would lie
            // outside the file.
            if (code == ZIP_ER_INVAL || code == ZIP_ER_SEEK || code == ZIP_ER_EOF || code == ZIP_ER_READ)
                fail_entry(index, "local header or data out of range of the file (truncated or corrupt archive)");
            fail_entry(index, reason(code, err));
        }
        return std::unique_ptr<zip_file_t, FileCloser>(f);
    }

    // Reads exactly out.size() bytes, or fails naming the entry.
    void fill(zip_file_t* f, std::size_t index, std::vector<unsigned char>& out) const {
        std::size_t pos = 0;
        while (pos < out.size()) {
            const zip_int64_t n = zip_fread(f, out.data() + pos, out.size() - pos);
            if (n < 0) {
                zip_error_t* err = zip_file_get_error(f);
                fail_entry(index, reason(zip_error_code_zip(err), err));
            }
            if (n == 0)
                fail_entry(index, "data ends after " + std::to_string(pos) + " of the " +
                                      std::to_string(entries[index].size) +
                                      " bytes the zip directory declares (truncated or corrupt archive)");
            pos += static_cast<std::size_t>(n);
        }
    }
};

// Opens a read-only archive and lists its entries. libzip's consistency check (ZIP_CHECKCONS:
// every local header against its central directory entry, so that a corrupt name or offset
// cannot go unnoticed) reports only "inconsistent", and refuses duplicate names outright. So the
// archive is opened with it first; when that fails, it is opened again without it to say which
// entry is wrong, or, when the only problem is a repeated name, to let the caller decide.
std::unique_ptr<ZipReader::Impl> ZipReader::Impl::open(const std::function<zip_source_t*()>& make_source,
                                                       std::string what) {
    auto impl = std::make_unique<ZipReader::Impl>();
    impl->what = std::move(what);
    auto try_open = [&](int flags, zip_error_t* error) -> zip_t* {
        zip_source_t* source = make_source();
        zip_t* za = zip_open_from_source(source, flags, error);
        if (za == nullptr) zip_source_free(source);
        return za;
    };
    ErrorGuard checked;
    impl->archive = try_open(ZIP_RDONLY | ZIP_CHECKCONS, &checked.error);
    const bool consistent = impl->archive != nullptr;
    if (!consistent) {
        ErrorGuard plain;
        impl->archive = try_open(ZIP_RDONLY, &plain.error);
        if (impl->archive == nullptr)
            throw IOError(impl->what + ": " + reason(zip_error_code_zip(&plain.error), &plain.error));
    }
    const zip_int64_t count = zip_get_num_entries(impl->archive, 0);
    if (count < 0) throw IOError(impl->what + ": cannot count the zip entries (corrupt archive)");
    impl->entries.reserve(static_cast<std::size_t>(count));
    impl->by_name.reserve(static_cast<std::size_t>(count));
    bool repeated = false;
    for (zip_int64_t i = 0; i < count; ++i) {
        zip_stat_t st;
        zip_stat_init(&st);
        const auto index = static_cast<zip_uint64_t>(i);
        if (zip_stat_index(impl->archive, index, ZIP_FL_ENC_RAW, &st) != 0 || !(st.valid & ZIP_STAT_NAME) ||
            !(st.valid & ZIP_STAT_SIZE) || !(st.valid & ZIP_STAT_COMP_SIZE))
            throw IOError(impl->what + ": central directory entry " + std::to_string(i) +
                          ": unreadable (corrupt archive)");
        impl->entries.push_back({st.name, st.size, st.comp_size});
        repeated |= !impl->by_name.emplace(impl->entries.back().name, impl->entries.size() - 1).second;
    }
    if (!consistent && !(repeated && zip_error_code_zip(&checked.error) == ZIP_ER_EXISTS)) {
        // Name the first entry whose directory record is wrong on its own (method, sizes, an
        // offset out of range); what remains is a local header that disagrees with it.
        for (std::size_t i = 0; i < impl->entries.size(); ++i) impl->open_entry(i, 0);
        throw IOError(impl->what + ": a local header disagrees with the central directory (corrupt archive)");
    }
    return impl;
}

ZipReader::ZipReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ZipReader::ZipReader(ZipReader&&) noexcept = default;
ZipReader& ZipReader::operator=(ZipReader&&) noexcept = default;
ZipReader::~ZipReader() = default;

ZipReader ZipReader::open_file(const std::string& path) {
    const std::uint64_t size = regular_file_size(path);
    if (size < kMinArchiveSize) throw IOError(path + ": not a zip archive: too short for a zip end record");
    auto source = [&path] {
        ErrorGuard e;
        zip_source_t* s = zip_source_file_create(path.c_str(), 0, -1, &e.error);
        if (s == nullptr) throw IOError(path + ": cannot open for reading: " + zip_error_strerror(&e.error));
        return s;
    };
    return ZipReader(Impl::open(source, path));
}

ZipReader ZipReader::open_memory(const void* data, std::size_t size, std::string what) {
    if (size < kMinArchiveSize) throw IOError(what + ": not a zip archive: too short for a zip end record");
    auto source = [&] {
        ErrorGuard e;
        zip_source_t* s = zip_source_buffer_create(data, size, 0, &e.error);
        if (s == nullptr) throw IOError(what + ": " + reason(zip_error_code_zip(&e.error), &e.error));
        return s;
    };
    return ZipReader(Impl::open(source, what));
}

const std::string& ZipReader::what() const { return impl_->what; }

const std::vector<ZipEntryInfo>& ZipReader::entries() const { return impl_->entries; }

const ZipEntryInfo* ZipReader::find(const std::string& name) const {
    const auto it = impl_->by_name.find(name);
    return it == impl_->by_name.end() ? nullptr : &impl_->entries[it->second];
}

std::size_t ZipReader::index_of(const ZipEntryInfo& entry) const {
    const std::vector<ZipEntryInfo>& all = impl_->entries;
    if (all.empty() || &entry < all.data() || &entry >= all.data() + all.size())
        throw std::invalid_argument("ZipReader::index_of: not an entry of this archive");
    return static_cast<std::size_t>(&entry - all.data());
}

std::vector<unsigned char> ZipReader::read(std::size_t index, std::uint64_t max_bytes) const {
    auto file = impl_->open_entry(index, max_bytes);
    const ZipEntryInfo& e = impl_->entries[index];
    if (e.size > max_bytes)
        impl_->fail_entry(index, "declares " + std::to_string(e.size) + " bytes, more than the " +
                                     std::to_string(max_bytes) + " the reader allows for it (corrupt archive or zip bomb)");
    std::vector<unsigned char> out(static_cast<std::size_t>(e.size));
    impl_->fill(file.get(), index, out);
    // One byte more must be the end: a stream that goes on past the declared size is refused
    // without inflating the rest. Reaching the end also makes libzip compare the CRC-32.
    unsigned char extra = 0;
    const zip_int64_t n = zip_fread(file.get(), &extra, 1);
    if (n < 0) {
        zip_error_t* err = zip_file_get_error(file.get());
        impl_->fail_entry(index, reason(zip_error_code_zip(err), err));
    }
    if (n > 0)
        impl_->fail_entry(index, "inflates to more than the " + std::to_string(e.size) +
                                     " bytes the zip directory declares (corrupt archive or zip bomb)");
    return out;
}

void ZipReader::verify(std::size_t index) const {
    auto file = impl_->open_entry(index, 0);
    const ZipEntryInfo& e = impl_->entries[index];
    std::vector<unsigned char> buffer(std::size_t(1) << 16);
    std::uint64_t total = 0;
    for (;;) {
        // Ask for at most one byte past the declared size, so a longer stream is caught there.
        const std::uint64_t want = std::min<std::uint64_t>(buffer.size(), e.size - std::min(total, e.size) + 1);
        const zip_int64_t n = zip_fread(file.get(), buffer.data(), want);
        if (n < 0) {
            zip_error_t* err = zip_file_get_error(file.get());
            impl_->fail_entry(index, reason(zip_error_code_zip(err), err));
        }
        if (n == 0) break;
        total += static_cast<std::uint64_t>(n);
        if (total > e.size)
            impl_->fail_entry(index, "inflates to more than the " + std::to_string(e.size) +
                                         " bytes the zip directory declares (corrupt archive or zip bomb)");
    }
    if (total < e.size)
        impl_->fail_entry(index, "data ends after " + std::to_string(total) + " of the " + std::to_string(e.size) +
                                     " bytes the zip directory declares (truncated or corrupt archive)");
}

std::vector<unsigned char> ZipReader::read_prefix(std::size_t index, std::size_t n) const {
    auto file = impl_->open_entry(index, n);
    const ZipEntryInfo& e = impl_->entries[index];
    std::vector<unsigned char> out(static_cast<std::size_t>(std::min<std::uint64_t>(n, e.size)));
    impl_->fill(file.get(), index, out);
    return out;
}

void write_zip(const std::string& path, const std::vector<ZipWriteEntry>& entries) {
    std::unordered_set<std::string> names;
    names.reserve(entries.size());
    for (std::size_t k = 0; k < entries.size(); ++k) {
        const ZipWriteEntry& e = entries[k];
        if (e.name.empty() || e.name.size() > 0xffff || e.name.find('\0') != std::string::npos)
            throw std::invalid_argument("write_zip: entries[" + std::to_string(k) +
                                        "].name is empty, too long or contains a NUL byte");
        if (!names.insert(e.name).second)
            throw std::invalid_argument("write_zip: entries[" + std::to_string(k) + "].name '" + e.name +
                                        "' repeats an earlier entry");
        if (e.data == nullptr && e.size != 0)
            throw std::invalid_argument("write_zip: entries[" + std::to_string(k) + "] ('" + e.name +
                                        "') has no data");
    }
    // The archive is assembled in memory by libzip (it seeks back to patch local headers), then
    // written through AtomicFile. Entry data is borrowed, not copied.
    ErrorGuard e;
    zip_source_t* buffer = zip_source_buffer_create(nullptr, 0, 0, &e.error);
    if (buffer == nullptr) throw IOError(path + ": " + reason(zip_error_code_zip(&e.error), &e.error));
    zip_source_keep(buffer);  // stays ours after zip_close, to read the result from
    struct SourceGuard {
        zip_source_t* s;
        ~SourceGuard() { zip_source_free(s); }
    } buffer_guard{buffer};
    zip_t* za = zip_open_from_source(buffer, ZIP_TRUNCATE, &e.error);
    if (za == nullptr) throw IOError(path + ": " + reason(zip_error_code_zip(&e.error), &e.error));
    auto fail = [&](const std::string& what) {
        const std::string why = reason(zip_error_code_zip(zip_get_error(za)), zip_get_error(za));
        zip_discard(za);
        throw IOError(path + ": " + what + ": " + why);
    };
    constexpr zip_uint16_t kDosDate = (0u << 9) | (1u << 5) | 1u;  // 1980-01-01, the zip epoch
    for (const ZipWriteEntry& entry : entries) {
        static const unsigned char kEmpty = 0;
        zip_source_t* data = zip_source_buffer(za, entry.size ? entry.data : &kEmpty, entry.size, 0);
        if (data == nullptr) fail("entry '" + entry.name + "'");
        const zip_int64_t index = zip_file_add(za, entry.name.c_str(), data, ZIP_FL_ENC_UTF_8);
        if (index < 0) {
            zip_source_free(data);
            fail("entry '" + entry.name + "'");
        }
        const auto i = static_cast<zip_uint64_t>(index);
        if (zip_set_file_compression(za, i, entry.deflate ? ZIP_CM_DEFLATE : ZIP_CM_STORE, 0) != 0 ||
            zip_file_set_dostime(za, i, 0, kDosDate, 0) != 0)
            fail("entry '" + entry.name + "'");
    }
    if (zip_close(za) != 0) fail("assembling the archive");
    zip_stat_t st;
    zip_stat_init(&st);
    if (zip_source_stat(buffer, &st) != 0 || !(st.valid & ZIP_STAT_SIZE) || zip_source_open(buffer) != 0)
        throw IOError(path + ": cannot read back the assembled archive");
    AtomicFile out(path);
    std::vector<unsigned char> chunk(std::size_t(1) << 20);
    zip_uint64_t done = 0;
    while (done < st.size) {
        const zip_int64_t n = zip_source_read(buffer, chunk.data(), chunk.size());
        if (n <= 0) {
            zip_source_close(buffer);
            throw IOError(path + ": cannot read back the assembled archive");
        }
        out.write(chunk.data(), static_cast<std::size_t>(n));
        done += static_cast<zip_uint64_t>(n);
    }
    zip_source_close(buffer);
    out.commit();
}

}  // namespace avsplat::io
