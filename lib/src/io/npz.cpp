// .npy / .npz reading and writing (io/npz.h). The zip layout follows PKWARE's APPNOTE
// (sections 4.3 and 4.5: local headers, central directory, end records, zip64 extra field);
// the .npy header follows numpy's format.py (NEP 1). Deflate is zlib's raw deflate.
#include "avsplat/io/npz.h"

#include "avsplat/core/error.h"
#include "avsplat/io/atomic_file.h"
#include "io/input_file.h"

#include <Eigen/Core>

#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <type_traits>

namespace avsplat {

namespace {

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
constexpr bool kHostLittleEndian = false;
#else
constexpr bool kHostLittleEndian = true;
#endif

struct TypeInfo {
    NpyType type;
    char kind;  // numpy's kind character: b (bool), i, u, f
    std::size_t size;
    const char* name;
};

constexpr TypeInfo kTypes[] = {
    {NpyType::Bool, 'b', 1, "bool"},       {NpyType::Int8, 'i', 1, "int8"},
    {NpyType::Int16, 'i', 2, "int16"},     {NpyType::Int32, 'i', 4, "int32"},
    {NpyType::Int64, 'i', 8, "int64"},     {NpyType::UInt8, 'u', 1, "uint8"},
    {NpyType::UInt16, 'u', 2, "uint16"},   {NpyType::UInt32, 'u', 4, "uint32"},
    {NpyType::UInt64, 'u', 8, "uint64"},   {NpyType::Float16, 'f', 2, "float16"},
    {NpyType::Float32, 'f', 4, "float32"}, {NpyType::Float64, 'f', 8, "float64"},
};

const TypeInfo& info(NpyType type) {
    for (const auto& t : kTypes)
        if (t.type == type) return t;
    throw std::invalid_argument("NpyType: unknown value " + std::to_string(static_cast<int>(type)));
}

// ---------------------------------------------------------------------------------------------
// Little-endian field access on byte buffers whose bounds the caller has checked.

std::uint16_t le16(const unsigned char* p) { return std::uint16_t(p[0] | (p[1] << 8)); }
std::uint32_t le32(const unsigned char* p) {
    return std::uint32_t(p[0]) | (std::uint32_t(p[1]) << 8) | (std::uint32_t(p[2]) << 16) |
           (std::uint32_t(p[3]) << 24);
}
std::uint64_t le64(const unsigned char* p) { return le32(p) | (std::uint64_t(le32(p + 4)) << 32); }

void put16(std::vector<unsigned char>& out, std::uint32_t v) {
    out.push_back(static_cast<unsigned char>(v & 0xff));
    out.push_back(static_cast<unsigned char>((v >> 8) & 0xff));
}
void put32(std::vector<unsigned char>& out, std::uint32_t v) {
    put16(out, v & 0xffff);
    put16(out, v >> 16);
}

// ---------------------------------------------------------------------------------------------
// Element conversion.

// float16 -> float32 is exact; Eigen's half does the bit work (NaN payloads, subnormals).
float half_to_float(std::uint16_t h) {
    return static_cast<float>(Eigen::half(Eigen::half_impl::raw_uint16_to_half(h)));
}

template <class T>
T load(const unsigned char* p) {
    T v;
    std::memcpy(&v, p, sizeof(T));
    return v;
}

// Calls f(double-or-exact value) for every element; Out is float or double.
template <class Out>
std::vector<Out> convert(const NpyArray& a) {
    const std::size_t n = a.size();
    if (a.bytes.size() != n * npy_type_size(a.type))
        throw std::invalid_argument("NpyArray '" + a.name + "': " + std::to_string(a.bytes.size()) +
                                    " bytes do not match shape " + a.shape_string() + " of " +
                                    npy_type_name(a.type));
    std::vector<Out> out(n);
    const unsigned char* p = a.bytes.data();
    auto each = [&](auto tag) {
        using T = decltype(tag);
        for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<Out>(load<T>(p + i * sizeof(T)));
    };
    switch (a.type) {
        case NpyType::Bool:
            for (std::size_t i = 0; i < n; ++i) out[i] = p[i] != 0 ? Out(1) : Out(0);
            break;
        case NpyType::Int8: each(std::int8_t{}); break;
        case NpyType::Int16: each(std::int16_t{}); break;
        case NpyType::Int32: each(std::int32_t{}); break;
        case NpyType::Int64: each(std::int64_t{}); break;
        case NpyType::UInt8: each(std::uint8_t{}); break;
        case NpyType::UInt16: each(std::uint16_t{}); break;
        case NpyType::UInt32: each(std::uint32_t{}); break;
        case NpyType::UInt64: each(std::uint64_t{}); break;
        case NpyType::Float16:
            for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<Out>(half_to_float(load<std::uint16_t>(p + 2 * i)));
            break;
        case NpyType::Float32: each(float{}); break;
        case NpyType::Float64: each(double{}); break;
    }
    return out;
}

void byteswap_elements(std::vector<unsigned char>& bytes, std::size_t element_size) {
    if (element_size < 2) return;
    for (std::size_t i = 0; i + element_size <= bytes.size(); i += element_size)
        std::reverse(bytes.begin() + static_cast<std::ptrdiff_t>(i),
                     bytes.begin() + static_cast<std::ptrdiff_t>(i + element_size));
}

// ---------------------------------------------------------------------------------------------
// The .npy header: a Python dict literal {'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }

struct NpyHeader {
    std::string descr;
    bool fortran_order = false;
    std::vector<std::size_t> shape;
};

class HeaderParser {
public:
    HeaderParser(const std::string& text, const std::string& what) : s_(text), what_(what) {}

    NpyHeader parse() {
        NpyHeader h;
        bool have_descr = false, have_order = false, have_shape = false;
        expect('{');
        for (;;) {
            skip_space();
            if (peek() == '}') { ++i_; break; }
            const std::string key = parse_string();
            expect(':');
            skip_space();
            if (key == "descr") {
                if (peek() == '[') fail("structured dtypes (a list 'descr') are not supported");
                h.descr = parse_string();
                have_descr = true;
            } else if (key == "fortran_order") {
                h.fortran_order = parse_bool();
                have_order = true;
            } else if (key == "shape") {
                h.shape = parse_shape();
                have_shape = true;
            } else {
                fail("unexpected key '" + key + "'");
            }
            skip_space();
            if (peek() == ',') { ++i_; continue; }
            skip_space();
            if (peek() == '}') { ++i_; break; }
            fail("expected ',' or '}' in the dictionary");
        }
        skip_space();
        if (i_ != s_.size()) fail("unexpected text after the dictionary");
        if (!have_descr || !have_order || !have_shape)
            fail(std::string("missing key '") + (!have_descr ? "descr" : !have_order ? "fortran_order" : "shape") + "'");
        return h;
    }

private:
    [[noreturn]] void fail(const std::string& why) const {
        throw IOError(what_ + ": invalid .npy header (" + why + ")");
    }
    char peek() const { return i_ < s_.size() ? s_[i_] : '\0'; }
    void skip_space() {
        while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\n' || s_[i_] == '\t' || s_[i_] == '\r')) ++i_;
    }
    void expect(char c) {
        skip_space();
        if (peek() != c) fail(std::string("expected '") + c + "'");
        ++i_;
    }
    std::string parse_string() {
        skip_space();
        const char quote = peek();
        if (quote != '\'' && quote != '"') fail("expected a quoted string");
        const std::size_t end = s_.find(quote, i_ + 1);
        if (end == std::string::npos) fail("unterminated string");
        std::string out = s_.substr(i_ + 1, end - i_ - 1);
        i_ = end + 1;
        return out;
    }
    bool parse_bool() {
        if (s_.compare(i_, 4, "True") == 0) { i_ += 4; return true; }
        if (s_.compare(i_, 5, "False") == 0) { i_ += 5; return false; }
        fail("fortran_order is neither True nor False");
    }
    std::vector<std::size_t> parse_shape() {
        if (peek() != '(') fail("shape is not a tuple");
        ++i_;
        std::vector<std::size_t> shape;
        for (;;) {
            skip_space();
            if (peek() == ')') { ++i_; break; }
            if (!(peek() >= '0' && peek() <= '9')) fail("shape entry is not a non-negative integer");
            std::size_t v = 0;
            while (peek() >= '0' && peek() <= '9') {
                const std::size_t digit = static_cast<std::size_t>(peek() - '0');
                if (v > (std::numeric_limits<std::size_t>::max() - digit) / 10) fail("shape entry too large");
                v = v * 10 + digit;
                ++i_;
            }
            if (peek() == 'L') ++i_;  // Python 2 long literal, written by old numpy versions
            shape.push_back(v);
            skip_space();
            if (peek() == ',') { ++i_; continue; }
            skip_space();
            if (peek() == ')') { ++i_; break; }
            fail("expected ',' or ')' in the shape");
        }
        return shape;
    }

    const std::string& s_;
    const std::string& what_;
    std::size_t i_ = 0;
};

// Element type and whether the data is little endian, from a descr such as "<f4" or "|b1".
std::pair<NpyType, bool> parse_descr(const std::string& descr, const std::string& what) {
    auto bad = [&](const std::string& why) {
        return IOError(what + ": dtype '" + descr + "' " + why +
                       " (supported: bool, int8..int64, uint8..uint64, float16, float32, float64)");
    };
    if (descr.size() < 2) throw bad("is not understood");
    const char order = descr[0];
    if (order != '<' && order != '>' && order != '|' && order != '=') throw bad("is not understood");
    const char kind = descr[1];
    if (kind == 'O') throw bad("holds Python objects (pickled), which are not supported");
    std::size_t size = 0;
    std::size_t k = 2;
    for (; k < descr.size() && descr[k] >= '0' && descr[k] <= '9' && size < 64; ++k)
        size = size * 10 + static_cast<std::size_t>(descr[k] - '0');
    if (k != descr.size() || k == 2) throw bad("is not supported");
    for (const auto& t : kTypes)
        if (t.kind == kind && t.size == size) {
            const bool little = order == '<' || order == '|' || (order == '=' && kHostLittleEndian);
            return {t.type, little};
        }
    throw bad("is not supported");
}

// Product of the shape and the byte count, or an IOError when they overflow size_t.
std::size_t checked_bytes(const std::vector<std::size_t>& shape, std::size_t element_size,
                          const std::string& what) {
    std::size_t n = element_size;
    for (std::size_t d : shape) {
        if (d != 0 && n > std::numeric_limits<std::size_t>::max() / d)
            throw IOError(what + ": shape too large");
        n *= d;
    }
    return n;
}

// Reorders Fortran-order elements into C order.
std::vector<unsigned char> fortran_to_c(const std::vector<unsigned char>& in,
                                        const std::vector<std::size_t>& shape, std::size_t element_size) {
    std::vector<unsigned char> out(in.size());
    const std::size_t rank = shape.size();
    std::size_t count = 1;
    for (std::size_t d : shape) count *= d;
    if (count == 0 || rank < 2) return in;
    std::vector<std::size_t> stride(rank, 1);  // Fortran strides in elements
    for (std::size_t k = 1; k < rank; ++k) stride[k] = stride[k - 1] * shape[k - 1];
    std::vector<std::size_t> index(rank, 0);
    std::size_t source = 0;
    for (std::size_t c = 0; c < count; ++c) {
        std::memcpy(&out[c * element_size], &in[source * element_size], element_size);
        // Advance the C-order index (last axis fastest), keeping the Fortran offset in step.
        for (std::size_t k = rank; k-- > 0;) {
            if (++index[k] < shape[k]) { source += stride[k]; break; }
            source -= stride[k] * (shape[k] - 1);
            index[k] = 0;
        }
    }
    return out;
}

// ---------------------------------------------------------------------------------------------
// Files.

class InputFile {
public:
    explicit InputFile(const std::string& path) : path_(path), in_((io::regular_file_size(path), path), std::ios::binary) {
        if (!in_) throw IOError(path + ": cannot open for reading");
        in_.seekg(0, std::ios::end);
        const std::streamoff end = in_.tellg();
        if (end < 0) throw IOError(path + ": cannot determine the file size");
        size_ = static_cast<std::uint64_t>(end);
    }
    std::uint64_t size() const { return size_; }
    // Reads n bytes at offset; the caller has checked offset + n <= size().
    void read(std::uint64_t offset, void* out, std::size_t n, const std::string& what) {
        if (n == 0) return;
        in_.clear();
        in_.seekg(static_cast<std::streamoff>(offset));
        in_.read(static_cast<char*>(out), static_cast<std::streamsize>(n));
        if (!in_ || static_cast<std::size_t>(in_.gcount()) != n) throw IOError(what + ": read failed");
    }
    std::vector<unsigned char> read(std::uint64_t offset, std::uint64_t n, const std::string& what) {
        if (offset > size_ || n > size_ - offset)
            throw IOError(what + ": extends past the end of the file (truncated or corrupt archive)");
        std::vector<unsigned char> buf(static_cast<std::size_t>(n));
        read(offset, buf.data(), buf.size(), what);
        return buf;
    }

private:
    std::string path_;
    std::ifstream in_;
    std::uint64_t size_ = 0;
};

std::vector<unsigned char> inflate_raw(const std::vector<unsigned char>& in, std::uint64_t out_size,
                                       const std::string& what) {
    std::vector<unsigned char> out(static_cast<std::size_t>(out_size));
    z_stream zs{};
    if (inflateInit2(&zs, -MAX_WBITS) != Z_OK) throw IOError(what + ": zlib inflateInit failed");
    // zlib counts in uInt (32 bits): feed and drain in chunks so that entries over 4 GiB work.
    constexpr std::size_t kChunk = std::size_t(1) << 30;
    std::size_t in_pos = 0, out_pos = 0;
    int rc = Z_OK;
    while (rc == Z_OK) {
        if (zs.avail_in == 0 && in_pos < in.size()) {
            const std::size_t n = std::min(kChunk, in.size() - in_pos);
            zs.next_in = const_cast<Bytef*>(in.data() + in_pos);
            zs.avail_in = static_cast<uInt>(n);
            in_pos += n;
        }
        if (zs.avail_out == 0 && out_pos < out.size()) {
            const std::size_t n = std::min(kChunk, out.size() - out_pos);
            zs.next_out = out.data() + out_pos;
            zs.avail_out = static_cast<uInt>(n);
            out_pos += n;
        }
        const uInt before_in = zs.avail_in, before_out = zs.avail_out;
        rc = inflate(&zs, Z_NO_FLUSH);
        // No progress with input and output left means the stream wants more than there is.
        if (rc == Z_BUF_ERROR || (rc == Z_OK && zs.avail_in == before_in && zs.avail_out == before_out))
            break;
    }
    const bool complete = rc == Z_STREAM_END && zs.total_out == out_size;
    const bool leftover = zs.avail_in != 0 || in_pos != in.size();
    const char* msg = zs.msg;
    inflateEnd(&zs);
    if (!complete || leftover)
        throw IOError(what + ": corrupt deflate data" + (msg ? std::string(" (") + msg + ")" : std::string()) +
                      " or wrong sizes in the zip directory");
    return out;
}

std::uint32_t crc32_of(const unsigned char* data, std::size_t n) {
    uLong crc = crc32(0L, Z_NULL, 0);
    constexpr std::size_t kChunk = std::size_t(1) << 30;
    for (std::size_t pos = 0; pos < n; pos += kChunk)
        crc = crc32(crc, data + pos, static_cast<uInt>(std::min(kChunk, n - pos)));
    return static_cast<std::uint32_t>(crc);
}

struct ZipEntry {
    std::string name;
    std::uint16_t flags = 0;
    std::uint16_t method = 0;
    std::uint32_t crc = 0;
    std::uint64_t compressed = 0;
    std::uint64_t uncompressed = 0;
    std::uint64_t local_offset = 0;
};

constexpr std::uint32_t kLocalSig = 0x04034b50, kCentralSig = 0x02014b50, kEndSig = 0x06054b50;
constexpr std::uint32_t kZip64EndSig = 0x06064b50, kZip64LocatorSig = 0x07064b50;

struct Directory {
    std::uint64_t entries = 0, offset = 0, size = 0;
    std::uint64_t end = 0;  // where the central directory must end (the first end record)
};

Directory find_directory(InputFile& file, const std::string& path) {
    const std::uint64_t size = file.size();
    if (size < 22) throw IOError(path + ": not an .npz (zip) archive: too short for a zip end record");
    const std::uint64_t tail_size = std::min<std::uint64_t>(size, 22 + 0xffff);
    const std::vector<unsigned char> tail = file.read(size - tail_size, tail_size, path);
    // The end record is the last signature whose comment reaches exactly to the end of the file.
    std::size_t at = std::string::npos;
    for (std::size_t k = tail.size() - 22 + 1; k-- > 0;)
        if (le32(&tail[k]) == kEndSig && k + 22 + le16(&tail[k + 20]) == tail.size()) { at = k; break; }
    if (at == std::string::npos)
        throw IOError(path + ": not an .npz (zip) archive: no zip end record (truncated or not a zip file)");
    const unsigned char* e = &tail[at];
    const std::uint64_t end_pos = size - tail_size + at;
    Directory d;
    d.entries = le16(e + 10);
    d.size = le32(e + 12);
    d.offset = le32(e + 16);
    d.end = end_pos;
    const bool disks = le16(e + 4) != 0 || le16(e + 6) != 0;
    const bool maybe64 = d.entries == 0xffff || d.size == 0xffffffffu || d.offset == 0xffffffffu ||
                         le16(e + 4) == 0xffff;
    // A zip64 end record is announced by a locator just before the end record.
    if (end_pos >= 20) {
        const std::vector<unsigned char> loc = file.read(end_pos - 20, 20, path);
        if (le32(loc.data()) == kZip64LocatorSig) {
            const std::uint64_t rec_pos = le64(&loc[8]);
            if (rec_pos > end_pos - 20 || end_pos - 20 - rec_pos < 56)
                throw IOError(path + ": zip64 end record offset out of range (corrupt archive)");
            const std::vector<unsigned char> rec = file.read(rec_pos, 56, path);
            if (le32(rec.data()) != kZip64EndSig)
                throw IOError(path + ": zip64 end record signature missing (corrupt archive)");
            if (le32(&rec[16]) != 0 || le32(&rec[20]) != 0 || le32(&loc[4]) != 0 || le32(&loc[16]) > 1)
                throw IOError(path + ": multi-disk zip archives are not supported");
            d.entries = le64(&rec[32]);
            d.size = le64(&rec[40]);
            d.offset = le64(&rec[48]);
            d.end = rec_pos;
            return d;
        }
    }
    if (maybe64) throw IOError(path + ": zip64 archive without a zip64 end record (corrupt archive)");
    if (disks) throw IOError(path + ": multi-disk zip archives are not supported");
    return d;
}

struct Archive {
    Directory directory;
    std::vector<ZipEntry> entries;
};

Archive read_directory(InputFile& file, const std::string& path) {
    const Directory d = find_directory(file, path);
    if (d.offset > d.end || d.size > d.end - d.offset)
        throw IOError(path + ": central directory out of range (truncated or corrupt archive)");
    if (d.entries > d.size / 46)
        throw IOError(path + ": central directory too small for " + std::to_string(d.entries) +
                      " entries (corrupt archive)");
    const std::vector<unsigned char> cd = file.read(d.offset, d.size, path);
    std::vector<ZipEntry> entries;
    entries.reserve(static_cast<std::size_t>(d.entries));
    std::size_t pos = 0;
    for (std::uint64_t k = 0; k < d.entries; ++k) {
        const std::string where = path + ": central directory entry " + std::to_string(k);
        if (cd.size() - pos < 46 || le32(&cd[pos]) != kCentralSig)
            throw IOError(where + ": bad signature or truncated (corrupt archive)");
        const unsigned char* h = &cd[pos];
        ZipEntry z;
        z.flags = le16(h + 8);
        z.method = le16(h + 10);
        z.crc = le32(h + 16);
        z.compressed = le32(h + 20);
        z.uncompressed = le32(h + 24);
        const std::size_t name_len = le16(h + 28), extra_len = le16(h + 30), comment_len = le16(h + 32);
        const std::uint16_t disk = le16(h + 34);
        z.local_offset = le32(h + 42);
        if (cd.size() - pos - 46 < name_len + extra_len + comment_len)
            throw IOError(where + ": name or extra field past the directory (corrupt archive)");
        z.name.assign(reinterpret_cast<const char*>(h + 46), name_len);
        // Zip64 extended information (header id 1): the 8-byte values of the fields whose
        // 4-byte slot holds 0xffffffff, in the order uncompressed, compressed, offset.
        const unsigned char* extra = h + 46 + name_len;
        for (std::size_t e = 0; e + 4 <= extra_len;) {
            const std::uint16_t id = le16(extra + e);
            const std::size_t len = le16(extra + e + 2);
            if (e + 4 + len > extra_len)
                throw IOError(where + " ('" + z.name + "'): extra field past its end (corrupt archive)");
            if (id == 1) {
                std::size_t f = e + 4;
                auto take = [&](std::uint64_t& field) {
                    if (field != 0xffffffffu) return;
                    if (f + 8 > e + 4 + len)
                        throw IOError(where + " ('" + z.name + "'): zip64 extra field too short (corrupt archive)");
                    field = le64(extra + f);
                    f += 8;
                };
                take(z.uncompressed);
                take(z.compressed);
                take(z.local_offset);
            }
            e += 4 + len;
        }
        if (disk != 0 && disk != 0xffff) throw IOError(path + ": multi-disk zip archives are not supported");
        entries.push_back(std::move(z));
        pos += 46 + name_len + extra_len + comment_len;
    }
    return {d, std::move(entries)};
}

bool ends_with(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Checks the entry's local header against the central directory and returns where its data
// starts. Done for every entry, arrays or not, so that a corrupt name cannot hide an array.
std::uint64_t locate_data(InputFile& file, const ZipEntry& z, std::uint64_t data_limit, const std::string& what) {
    if (z.local_offset > data_limit || data_limit - z.local_offset < 30)
        throw IOError(what + ": local header offset out of range (corrupt archive)");
    const std::vector<unsigned char> lh = file.read(z.local_offset, 30, what);
    if (le32(lh.data()) != kLocalSig) throw IOError(what + ": bad local header signature (corrupt archive)");
    const std::uint64_t data_pos = z.local_offset + 30 + le16(&lh[26]) + le16(&lh[28]);
    if (data_pos > data_limit || z.compressed > data_limit - data_pos)
        throw IOError(what + ": data extends past the end of the entries (truncated or corrupt archive)");
    const std::vector<unsigned char> local_name = file.read(z.local_offset + 30, le16(&lh[26]), what);
    if (std::string(local_name.begin(), local_name.end()) != z.name)
        throw IOError(what + ": local header names a different entry (corrupt archive)");
    return data_pos;
}

std::vector<unsigned char> read_entry(InputFile& file, const ZipEntry& z, std::uint64_t data_pos,
                                      const std::string& what) {
    if (z.flags & 0x1) throw IOError(what + ": encrypted entries are not supported");
    if (z.method != 0 && z.method != 8)
        throw IOError(what + ": compression method " + std::to_string(z.method) +
                      " is not supported (stored or deflate only)");
    // Deflate cannot expand data by more than about 1032:1; a larger claim is corruption, and
    // checking it keeps a corrupt size from allocating terabytes.
    if (z.method == 0 ? z.uncompressed != z.compressed
                      : z.uncompressed > z.compressed * 1040 + 1024)
        throw IOError(what + ": sizes in the zip directory are inconsistent (corrupt archive)");
    if (z.uncompressed > std::numeric_limits<std::size_t>::max())
        throw IOError(what + ": entry too large for this machine");
    std::vector<unsigned char> raw = file.read(data_pos, z.compressed, what);
    if (z.method == 8) raw = inflate_raw(raw, z.uncompressed, what);
    if (crc32_of(raw.data(), raw.size()) != z.crc) throw IOError(what + ": CRC-32 mismatch (corrupt data)");
    return raw;
}

// ---------------------------------------------------------------------------------------------
// Writing.

template <class T> constexpr NpyType type_of();
template <> constexpr NpyType type_of<bool>() { return NpyType::Bool; }
template <> constexpr NpyType type_of<std::int8_t>() { return NpyType::Int8; }
template <> constexpr NpyType type_of<std::int16_t>() { return NpyType::Int16; }
template <> constexpr NpyType type_of<std::int32_t>() { return NpyType::Int32; }
template <> constexpr NpyType type_of<std::int64_t>() { return NpyType::Int64; }
template <> constexpr NpyType type_of<std::uint8_t>() { return NpyType::UInt8; }
template <> constexpr NpyType type_of<std::uint16_t>() { return NpyType::UInt16; }
template <> constexpr NpyType type_of<std::uint32_t>() { return NpyType::UInt32; }
template <> constexpr NpyType type_of<std::uint64_t>() { return NpyType::UInt64; }
template <> constexpr NpyType type_of<float>() { return NpyType::Float32; }
template <> constexpr NpyType type_of<double>() { return NpyType::Float64; }

std::vector<unsigned char> npy_image(const NpyArray& a) {
    const TypeInfo& t = info(a.type);
    std::string dict = std::string("{'descr': '") + (t.size == 1 ? '|' : '<') + t.kind +
                       std::to_string(t.size) + "', 'fortran_order': False, 'shape': (";
    for (std::size_t k = 0; k < a.shape.size(); ++k) dict += (k ? ", " : "") + std::to_string(a.shape[k]);
    dict += a.shape.size() == 1 ? ",), }" : "), }";
    // numpy pads the header with spaces and a newline so that the data starts at a multiple of 64.
    const bool v2 = dict.size() + 11 + 64 > 0xffff;
    const std::size_t prefix = v2 ? 12 : 10;
    const std::size_t total = (prefix + dict.size() + 1 + 63) / 64 * 64;
    dict.append(total - prefix - dict.size() - 1, ' ');
    dict += '\n';
    std::vector<unsigned char> out = {0x93, 'N', 'U', 'M', 'P', 'Y', static_cast<unsigned char>(v2 ? 2 : 1), 0};
    if (v2) put32(out, static_cast<std::uint32_t>(dict.size()));
    else put16(out, static_cast<std::uint32_t>(dict.size()));
    out.insert(out.end(), dict.begin(), dict.end());
    const std::size_t data_pos = out.size();
    out.insert(out.end(), a.bytes.begin(), a.bytes.end());
    if (!kHostLittleEndian) {
        std::vector<unsigned char> data(out.begin() + static_cast<std::ptrdiff_t>(data_pos), out.end());
        byteswap_elements(data, t.size);
        std::copy(data.begin(), data.end(), out.begin() + static_cast<std::ptrdiff_t>(data_pos));
    }
    return out;
}

std::vector<unsigned char> deflate_raw(const std::vector<unsigned char>& in, const std::string& what) {
    z_stream zs{};
    if (deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY) != Z_OK)
        throw IOError(what + ": zlib deflateInit failed");
    std::vector<unsigned char> out(deflateBound(&zs, static_cast<uLong>(in.size())));
    zs.next_in = const_cast<Bytef*>(in.data());
    zs.avail_in = static_cast<uInt>(in.size());
    zs.next_out = out.data();
    zs.avail_out = static_cast<uInt>(out.size());
    const int rc = deflate(&zs, Z_FINISH);
    out.resize(zs.total_out);
    deflateEnd(&zs);
    if (rc != Z_STREAM_END) throw IOError(what + ": zlib deflate failed");
    return out;
}

}  // namespace

// -------------------------------------------------------------------------------------------------

std::size_t npy_type_size(NpyType type) { return info(type).size; }

const char* npy_type_name(NpyType type) { return info(type).name; }

std::size_t NpyArray::size() const {
    std::size_t n = 1;
    for (std::size_t d : shape) n *= d;
    return n;
}

std::string NpyArray::shape_string() const {
    std::string s = "(";
    for (std::size_t k = 0; k < shape.size(); ++k) s += (k ? ", " : "") + std::to_string(shape[k]);
    return s + (shape.size() == 1 ? ",)" : ")");
}

std::vector<float> NpyArray::to_float32() const { return convert<float>(*this); }

std::vector<double> NpyArray::to_float64() const { return convert<double>(*this); }

template <class T>
NpyArray NpyArray::from_data(std::string name, std::vector<std::size_t> shape, const T* data) {
    NpyArray a;
    a.name = std::move(name);
    a.type = type_of<T>();
    a.shape = std::move(shape);
    const std::size_t n = a.size();
    if (n > 0 && data == nullptr)
        throw std::invalid_argument("NpyArray::from_data('" + a.name + "'): data is null for shape " + a.shape_string());
    a.bytes.resize(n * sizeof(T));
    if (n > 0) {
        if constexpr (std::is_same_v<T, bool>) {
            for (std::size_t i = 0; i < n; ++i) a.bytes[i] = data[i] ? 1 : 0;
        } else {
            std::memcpy(a.bytes.data(), data, a.bytes.size());
        }
    }
    return a;
}

template NpyArray NpyArray::from_data<bool>(std::string, std::vector<std::size_t>, const bool*);
template NpyArray NpyArray::from_data<std::int8_t>(std::string, std::vector<std::size_t>, const std::int8_t*);
template NpyArray NpyArray::from_data<std::int16_t>(std::string, std::vector<std::size_t>, const std::int16_t*);
template NpyArray NpyArray::from_data<std::int32_t>(std::string, std::vector<std::size_t>, const std::int32_t*);
template NpyArray NpyArray::from_data<std::int64_t>(std::string, std::vector<std::size_t>, const std::int64_t*);
template NpyArray NpyArray::from_data<std::uint8_t>(std::string, std::vector<std::size_t>, const std::uint8_t*);
template NpyArray NpyArray::from_data<std::uint16_t>(std::string, std::vector<std::size_t>, const std::uint16_t*);
template NpyArray NpyArray::from_data<std::uint32_t>(std::string, std::vector<std::size_t>, const std::uint32_t*);
template NpyArray NpyArray::from_data<std::uint64_t>(std::string, std::vector<std::size_t>, const std::uint64_t*);
template NpyArray NpyArray::from_data<float>(std::string, std::vector<std::size_t>, const float*);
template NpyArray NpyArray::from_data<double>(std::string, std::vector<std::size_t>, const double*);

NpyArray parse_npy(const unsigned char* data, std::size_t size, const std::string& what,
                   const std::string& name) {
    static const unsigned char kMagic[6] = {0x93, 'N', 'U', 'M', 'P', 'Y'};
    if (size < 10 || std::memcmp(data, kMagic, 6) != 0) throw IOError(what + ": not a .npy array (bad magic)");
    const unsigned major = data[6];
    if (major < 1 || major > 3)
        throw IOError(what + ": .npy format version " + std::to_string(major) + "." +
                      std::to_string(data[7]) + " is not supported (1.0, 2.0, 3.0)");
    const std::size_t prefix = major == 1 ? 10 : 12;
    if (size < prefix) throw IOError(what + ": truncated .npy header");
    const std::size_t header_len = major == 1 ? le16(data + 8) : le32(data + 8);
    if (header_len > size - prefix) throw IOError(what + ": truncated .npy header");
    // Version 3 allows UTF-8 in the header; the keys and values we accept are ASCII either way.
    const std::string header(reinterpret_cast<const char*>(data + prefix), header_len);
    const NpyHeader h = HeaderParser(header, what).parse();
    const auto [type, little] = parse_descr(h.descr, what);
    NpyArray a;
    a.name = name;
    a.type = type;
    a.shape = h.shape;
    const std::size_t element = npy_type_size(type);
    const std::size_t nbytes = checked_bytes(a.shape, element, what);
    const std::size_t available = size - prefix - header_len;
    if (available != nbytes)
        throw IOError(what + ": data has " + std::to_string(available) + " bytes, shape " +
                      a.shape_string() + " of " + npy_type_name(type) + " needs " +
                      std::to_string(nbytes) + " (truncated or corrupt)");
    const unsigned char* body = data + prefix + header_len;
    a.bytes.assign(body, body + nbytes);
    if (little != kHostLittleEndian) byteswap_elements(a.bytes, element);
    if (h.fortran_order) a.bytes = fortran_to_c(a.bytes, a.shape, element);
    return a;
}

NpyArray read_npy(const std::string& path) {
    InputFile file(path);
    const std::vector<unsigned char> image = file.read(0, file.size(), path);
    std::string name = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
    if (ends_with(name, ".npy")) name.resize(name.size() - 4);
    return parse_npy(image.data(), image.size(), path, name);
}

std::vector<NpyArray> read_npz(const std::string& path) {
    InputFile file(path);
    const Archive archive = read_directory(file, path);
    // Entry data lies before the central directory, whose offset therefore bounds it.
    const std::uint64_t data_limit = archive.directory.offset;
    std::vector<NpyArray> arrays;
    for (const ZipEntry& z : archive.entries) {
        const std::string what = path + ": entry '" + z.name + "'";
        const std::uint64_t data_pos = locate_data(file, z, data_limit, what);
        if (!ends_with(z.name, ".npy")) continue;
        std::string name = z.name.substr(0, z.name.size() - 4);
        if (find_array(arrays, name)) throw IOError(what + ": duplicate array name '" + name + "'");
        const std::vector<unsigned char> image = read_entry(file, z, data_pos, what);
        arrays.push_back(parse_npy(image.data(), image.size(), what, name));
    }
    return arrays;
}

const NpyArray* find_array(const std::vector<NpyArray>& arrays, const std::string& name) {
    for (const auto& a : arrays)
        if (a.name == name) return &a;
    return nullptr;
}

void write_npz(const std::string& path, const std::vector<NpyArray>& arrays, NpzCompression compression) {
    for (std::size_t k = 0; k < arrays.size(); ++k) {
        const NpyArray& a = arrays[k];
        if (a.name.empty() || a.name.size() > 0xfff0)
            throw std::invalid_argument("write_npz: arrays[" + std::to_string(k) + "].name is empty or too long");
        for (std::size_t j = 0; j < k; ++j)
            if (arrays[j].name == a.name)
                throw std::invalid_argument("write_npz: arrays[" + std::to_string(k) + "].name '" + a.name +
                                            "' repeats arrays[" + std::to_string(j) + "]");
        if (a.bytes.size() != a.size() * npy_type_size(a.type))
            throw std::invalid_argument("write_npz: arrays[" + std::to_string(k) + "] ('" + a.name + "'): " +
                                        std::to_string(a.bytes.size()) + " bytes do not match shape " +
                                        a.shape_string() + " of " + npy_type_name(a.type));
    }
    if (arrays.size() > 0xfffe) throw IOError(path + ": too many arrays for a zip archive without zip64");
    constexpr std::uint32_t kDate = (0u << 9) | (1u << 5) | 1u;  // 1980-01-01, the zip epoch
    std::vector<unsigned char> central;
    AtomicFile out(path);
    std::uint64_t offset = 0;
    for (const NpyArray& a : arrays) {
        const std::string entry = a.name + ".npy";
        const std::vector<unsigned char> image = npy_image(a);
        const std::uint32_t crc = crc32_of(image.data(), image.size());
        const bool deflated = compression == NpzCompression::Deflated;
        if (image.size() >= 0xffffffffu)
            throw IOError(path + ": entry '" + entry + "' needs zip64 (4 GiB or more), which write_npz does not write");
        const std::vector<unsigned char> body = deflated ? deflate_raw(image, path + ": entry '" + entry + "'") : image;
        if (offset + 30 + entry.size() + body.size() >= 0xffffffffu)
            throw IOError(path + ": the archive needs zip64 (4 GiB or more), which write_npz does not write");
        auto header = [&](std::vector<unsigned char>& h, bool is_central) {
            put32(h, is_central ? kCentralSig : kLocalSig);
            if (is_central) put16(h, 20);  // version made by
            put16(h, 20);                  // version needed to extract (deflate)
            put16(h, 0);                   // flags
            put16(h, deflated ? 8 : 0);
            put16(h, 0);                   // time 00:00:00
            put16(h, kDate);
            put32(h, crc);
            put32(h, static_cast<std::uint32_t>(body.size()));
            put32(h, static_cast<std::uint32_t>(image.size()));
            put16(h, static_cast<std::uint32_t>(entry.size()));
            put16(h, 0);  // extra field length
            if (is_central) {
                put16(h, 0);  // comment length
                put16(h, 0);  // disk number
                put16(h, 0);  // internal attributes
                put32(h, 0);  // external attributes
                put32(h, static_cast<std::uint32_t>(offset));
            }
            h.insert(h.end(), entry.begin(), entry.end());
        };
        std::vector<unsigned char> local;
        header(local, false);
        header(central, true);
        out.write(local.data(), local.size());
        out.write(body.data(), body.size());
        offset += local.size() + body.size();
    }
    std::vector<unsigned char> end;
    put32(end, kEndSig);
    put16(end, 0);
    put16(end, 0);
    put16(end, static_cast<std::uint32_t>(arrays.size()));
    put16(end, static_cast<std::uint32_t>(arrays.size()));
    put32(end, static_cast<std::uint32_t>(central.size()));
    put32(end, static_cast<std::uint32_t>(offset));
    put16(end, 0);
    out.write(central.data(), central.size());
    out.write(end.data(), end.size());
    out.commit();
}

}  // namespace avsplat
