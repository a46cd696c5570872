#include "io/spz/spz_container.h"

#include "avsplat/core/error.h"
#include "avsplat/core/interrupt.h"
#include "core/interrupt_poll.h"

#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <limits>
#include <memory>

namespace avsplat::io::spz {

namespace {

// Extension records of a v3 stream may add at most this much beyond the attribute blocks.
constexpr std::size_t kMaxLegacyExtensionBytes = 1 << 20;
// Decompressed output grows from this much, doubling, so that a header's claim costs memory only
// as far as the stream backs it.
constexpr std::size_t kFirstChunk = std::size_t(1) << 16;

std::uint32_t le32(const std::uint8_t* p) {
    return std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 | std::uint32_t(p[3]) << 24;
}
std::uint64_t le64(const std::uint8_t* p) { return std::uint64_t(le32(p)) | std::uint64_t(le32(p + 4)) << 32; }
void put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
    for (int k = 0; k < 4; ++k) out.push_back(static_cast<std::uint8_t>(v >> (8 * k)));
}
void put64(std::vector<std::uint8_t>& out, std::uint64_t v) {
    put32(out, static_cast<std::uint32_t>(v));
    put32(out, static_cast<std::uint32_t>(v >> 32));
}

[[noreturn]] void fail(const std::string& name, const std::string& what) { throw IOError(name + ": " + what); }

// No deflate stream expands more than 1032 times (its longest match, 258 bytes, costs at least
// two bits). A gzipped (v2, v3) header implying more than this many times the file's size (plus a
// little for tiny files) is a lie or a bomb, refused before any decompression; so memory stays
// within a fixed multiple of the file's size.
constexpr std::uint64_t kMaxRatio = 1032;
constexpr std::uint64_t kRatioSlack = 1 << 20;

void check_ratio(std::uint64_t implied, std::uint32_t count, std::size_t file_size, const std::string& name) {
    if (implied > kRatioSlack + kMaxRatio * std::uint64_t(file_size))
        fail(name, "numPoints: " + std::to_string(count) + " Gaussians need " + std::to_string(implied) +
                       " bytes, more than a " + std::to_string(file_size) +
                       "-byte file can hold (1032 times its size, deflate's limit)");
}


// The six attribute blocks: names (for messages) and bytes per Gaussian.
struct Layout {
    std::array<const char*, 6> names{{"positions", "alphas", "colors", "scales", "rotations", "sh"}};
    std::array<std::uint64_t, 6> bytes{};
    std::uint64_t total() const {
        std::uint64_t t = 0;
        for (auto b : bytes) t += b;
        return t;
    }
};

Layout layout_for(int version, std::uint32_t count, int sh_degree) {
    Layout l;
    const std::uint64_t n = count;
    l.bytes = {9 * n, n, 3 * n, 3 * n, (version >= 3 ? 4 : 3) * n,
               3 * std::uint64_t(sh_rest_for_degree(sh_degree)) * n};
    return l;
}

std::vector<std::uint8_t>* block(PackedSpz& p, int k) {
    std::vector<std::uint8_t>* blocks[6] = {&p.positions, &p.alphas, &p.colors, &p.scales, &p.rotations, &p.sh};
    return blocks[k];
}

bool is_gzip(const std::uint8_t* data, std::size_t size) { return size >= 2 && data[0] == 0x1f && data[1] == 0x8b; }

// A gzip member inflated piece by piece.
class Inflater {
public:
    Inflater(const std::uint8_t* data, std::size_t size, const std::string& name) : name_(name) {
        if (inflateInit2(&z_, 16 + MAX_WBITS) != Z_OK) fail(name, "gzip: cannot initialise zlib");
        z_.next_in = const_cast<Bytef*>(data);
        // zlib counts input in uInt: feed a larger file in slices.
        remaining_ = size;
        refill();
    }
    ~Inflater() { inflateEnd(&z_); }
    Inflater(const Inflater&) = delete;
    Inflater& operator=(const Inflater&) = delete;

    bool ended() const { return ended_; }

    /// Appends up to `limit - out.size()` inflated bytes to `out`, growing it geometrically;
    /// stops at the end of the stream. Throws on corrupt or truncated data.
    void read_into(std::vector<std::uint8_t>& out, std::size_t limit) {
        while (!ended_ && out.size() < limit) {
            const std::size_t have = out.size();
            const std::size_t want = std::min(limit, std::max(have * 2, have + kFirstChunk));
            out.resize(want);
            z_.next_out = out.data() + have;
            const std::size_t avail = want - have;
            z_.avail_out = static_cast<uInt>(std::min<std::size_t>(avail, std::numeric_limits<uInt>::max()));
            const uInt before = z_.avail_out;
            const int rc = inflate(&z_, Z_NO_FLUSH);
            out.resize(have + (before - z_.avail_out));
            if (rc == Z_STREAM_END) {
                ended_ = true;
            } else if (rc == Z_BUF_ERROR && z_.avail_in == 0) {
                if (remaining_ == 0)
                    fail(name_, "gzip stream is truncated after " + std::to_string(z_.total_out) +
                                    " inflated bytes");
                refill();
            } else if (rc == Z_BUF_ERROR && before == z_.avail_out) {
                // No progress with input and room for output: never loop on it.
                fail(name_, "gzip stream is corrupt: inflate made no progress");
            } else if (rc != Z_OK && rc != Z_BUF_ERROR) {
                fail(name_, std::string("gzip stream is corrupt: ") + (z_.msg ? z_.msg : "inflate failed"));
            } else if (z_.avail_in == 0) {
                refill();
            }
        }
    }

private:
    void refill() {
        if (z_.avail_in != 0 || remaining_ == 0) return;
        const std::size_t n = std::min<std::size_t>(remaining_, std::numeric_limits<uInt>::max());
        z_.avail_in = static_cast<uInt>(n);
        remaining_ -= n;
    }

    z_stream z_{};
    std::size_t remaining_ = 0;
    bool ended_ = false;
    const std::string& name_;
};

// One ZSTD stream that must inflate to exactly `expected` bytes.
std::vector<std::uint8_t> unzstd(const std::uint8_t* data, std::size_t size, std::uint64_t expected,
                                 const std::string& name, const std::string& field) {
    if (size == 0 && expected == 0) return {};  // an empty block may be stored as no frame at all
    const unsigned long long declared = ZSTD_getFrameContentSize(data, size);
    if (declared == ZSTD_CONTENTSIZE_ERROR)
        fail(name, field + ": not a ZSTD frame");
    if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != expected)
        fail(name, field + ": ZSTD frame holds " + std::to_string(declared) + " bytes, the header implies " +
                       std::to_string(expected));
    std::unique_ptr<ZSTD_DStream, decltype(&ZSTD_freeDStream)> ds(ZSTD_createDStream(), &ZSTD_freeDStream);
    if (!ds) fail(name, field + ": cannot create a ZSTD decoder");
    // Frames needing a window beyond 128 MiB are refused (zstd's own default is the same limit).
    ZSTD_DCtx_setParameter(ds.get(), ZSTD_d_windowLogMax, 27);
    std::vector<std::uint8_t> out;
    ZSTD_inBuffer in{data, size, 0};
    std::size_t rc = 1;
    // One byte beyond `expected` is room enough to notice a stream that holds more.
    const std::size_t limit = static_cast<std::size_t>(expected) + 1;
    while (rc != 0) {
        const std::size_t have = out.size();
        if (have >= limit) break;
        const std::size_t want = std::min(limit, std::max(have * 2, have + kFirstChunk));
        out.resize(want);
        ZSTD_outBuffer ob{out.data() + have, want - have, 0};
        const std::size_t consumed = in.pos;
        rc = ZSTD_decompressStream(ds.get(), &ob, &in);
        out.resize(have + ob.pos);
        if (ZSTD_isError(rc)) fail(name, field + ": ZSTD stream is corrupt: " + ZSTD_getErrorName(rc));
        if (rc != 0 && in.pos == in.size && ob.pos < ob.size)
            fail(name, field + ": ZSTD stream is truncated after " + std::to_string(out.size()) + " bytes");
        if (rc != 0 && in.pos == consumed && ob.pos == 0)  // no progress: never loop on it
            fail(name, field + ": ZSTD stream is corrupt: the decoder made no progress");
    }
    if (out.size() > expected)
        fail(name, field + ": ZSTD stream holds more than the " + std::to_string(expected) +
                       " bytes that the header implies");
    if (out.size() < expected)
        fail(name, field + ": ZSTD stream holds " + std::to_string(out.size()) + " bytes, the header implies " +
                       std::to_string(expected));
    if (in.pos != in.size)
        fail(name, field + ": " + std::to_string(in.size - in.pos) + " bytes follow the ZSTD frame");
    return out;
}

struct CommonHeader {
    std::uint32_t version, count;
    int sh_degree, fractional_bits;
    std::uint8_t flags;
};

CommonHeader parse_common(const std::uint8_t* h, const std::string& name) {
    if (le32(h) != kMagic) fail(name, "magic: not an SPZ file (no \"NGSP\" header)");
    CommonHeader c{le32(h + 4), le32(h + 8), h[12], h[13], h[14]};
    if (c.version < 2 || c.version > 4)
        fail(name, "version: " + std::to_string(c.version) + " is not supported (2, 3 and 4 are)");
    if (c.sh_degree > 4) fail(name, "shDegree: " + std::to_string(c.sh_degree) + " is outside 0..4");
    return c;
}

void fill(PackedSpz& p, const CommonHeader& c) {
    p.version = static_cast<int>(c.version);
    p.count = c.count;
    p.sh_degree = c.sh_degree;
    p.fractional_bits = c.fractional_bits;
    p.antialiased = (c.flags & kFlagAntialiased) != 0;
}

// Extension records [uint32 type][uint32 byteLength][payload] tiling [begin, end).
void parse_extensions(const std::uint8_t* begin, const std::uint8_t* end, PackedSpz& p, const std::string& name) {
    const std::uint8_t* at = begin;
    int index = 0;
    while (at < end) {
        const std::string field = "extension[" + std::to_string(index) + "]";
        if (end - at < 8) fail(name, field + ": record header is truncated");
        const std::uint32_t type = le32(at), length = le32(at + 4);
        if (length > static_cast<std::uint64_t>(end - at - 8))
            fail(name, field + ": byteLength " + std::to_string(length) + " runs past the extension area");
        if (type == kExtensionCoordinateSystem) {
            if (length < 4) fail(name, field + ": coordinate-system record is shorter than 4 bytes");
            const std::uint32_t axes = le32(at + 8);
            if (axes >= 1 && axes <= 8)
                p.coordinate_system = static_cast<SpzCoordinateSystem>(axes - 1);
            else if (axes != 0)
                fail(name, field + ": coordinate system " + std::to_string(axes) +
                               " (a 90-degree rotated family) is not supported");
        }
        at += 8 + std::size_t(length);
        ++index;
    }
}

PackedSpz unpack_v4(const std::uint8_t* data, std::size_t size, const std::string& name) {
    if (size < kHeaderSize) fail(name, "header: file is " + std::to_string(size) + " bytes, shorter than the 32-byte header");
    const CommonHeader c = parse_common(data, name);
    if (c.version != 4) fail(name, "version: " + std::to_string(c.version) + " outside a gzip stream (only 4 is plain)");
    PackedSpz p;
    fill(p, c);
    const Layout l = layout_for(4, c.count, c.sh_degree);
    const int streams = data[15];
    const int expected_streams = c.sh_degree > 0 ? 6 : 5;
    if (streams != expected_streams)
        fail(name, "numStreams: " + std::to_string(streams) + ", expected " + std::to_string(expected_streams) +
                       " for SH degree " + std::to_string(c.sh_degree));
    const std::uint64_t toc = le32(data + 16);
    if (toc < kHeaderSize || toc + 16 * std::uint64_t(streams) > size)
        fail(name, "tocByteOffset: " + std::to_string(toc) + " puts the table of contents outside the " +
                       std::to_string(size) + "-byte file");
    if (c.flags & kFlagHasExtensions) parse_extensions(data + kHeaderSize, data + toc, p, name);
    // No ratio bound here: ZSTD stores a run of equal bytes in a few bytes per 128 KiB block, so a
    // cloud of identical Gaussians is legitimately thousands of times smaller than its blocks.
    // Each frame's declared content size must match the header instead, and unzstd grows its
    // buffer only as the decoder really produces output.
    std::uint64_t offset = toc + 16 * std::uint64_t(streams);
    // Check every entry before decompressing any, so that a lying table costs nothing.
    std::array<std::uint64_t, 6> compressed{};
    for (int k = 0; k < streams; ++k) {
        const std::uint8_t* e = data + toc + 16 * k;
        const std::string field = std::string("toc[") + std::to_string(k) + "] (" + l.names[k] + ")";
        compressed[k] = le64(e);
        const std::uint64_t uncompressed = le64(e + 8);
        if (uncompressed != l.bytes[k])
            fail(name, field + ": uncompressedSize " + std::to_string(uncompressed) + ", the header implies " +
                           std::to_string(l.bytes[k]) + " for " + std::to_string(c.count) + " Gaussians");
        if (compressed[k] > size - offset)
            fail(name, field + ": compressedSize " + std::to_string(compressed[k]) + " runs past the end of the file");
        if (compressed[k] > 0) {
            const unsigned long long declared = ZSTD_getFrameContentSize(data + offset, std::size_t(compressed[k]));
            if (declared == ZSTD_CONTENTSIZE_ERROR) fail(name, field + ": not a ZSTD frame");
            if (declared != ZSTD_CONTENTSIZE_UNKNOWN && declared != uncompressed)
                fail(name, field + ": ZSTD frame holds " + std::to_string(declared) + " bytes, the header implies " +
                               std::to_string(uncompressed));
        }
        offset += compressed[k];
    }
    offset = toc + 16 * std::uint64_t(streams);
    for (int k = 0; k < streams; ++k) {
        *block(p, k) = unzstd(data + offset, static_cast<std::size_t>(compressed[k]), l.bytes[k], name, l.names[k]);
        offset += compressed[k];
    }
    return p;
}

PackedSpz unpack_legacy(const std::uint8_t* data, std::size_t size, const std::string& name) {
    Inflater z(data, size, name);
    std::vector<std::uint8_t> bytes;
    z.read_into(bytes, kLegacyHeaderSize);
    if (bytes.size() < kLegacyHeaderSize)
        fail(name, "header: the gzip stream holds " + std::to_string(bytes.size()) + " bytes, fewer than the 16-byte header");
    const CommonHeader c = parse_common(bytes.data(), name);
    if (c.version == 4) fail(name, "version: 4 inside a gzip stream (v4 files are not gzipped)");
    PackedSpz p;
    fill(p, c);
    const Layout l = layout_for(static_cast<int>(c.version), c.count, c.sh_degree);
    const std::uint64_t expected = kLegacyHeaderSize + l.total();
    check_ratio(expected, c.count, size, name);
    const bool extensions = (c.flags & kFlagHasExtensions) != 0;
    const std::uint64_t limit = expected + (extensions ? kMaxLegacyExtensionBytes : 0) + 1;
    if (limit > std::numeric_limits<std::size_t>::max()) fail(name, "numPoints: too large for this machine");
    z.read_into(bytes, static_cast<std::size_t>(limit));
    const std::uint64_t got = bytes.size();
    if (got < expected)
        fail(name, "numPoints: the header claims " + std::to_string(c.count) + " Gaussians (" +
                       std::to_string(expected) + " bytes), the gzip stream holds " + std::to_string(got));
    if (!z.ended() || (!extensions && got != expected))
        fail(name, "numPoints: the gzip stream holds more than the " + std::to_string(expected) +
                       " bytes that the header's " + std::to_string(c.count) + " Gaussians imply");
    // Extension records (flag 0x2) sit between the header and the attribute blocks.
    const std::size_t ext = static_cast<std::size_t>(got - expected);
    if (extensions) parse_extensions(bytes.data() + kLegacyHeaderSize, bytes.data() + kLegacyHeaderSize + ext, p, name);
    std::size_t at = kLegacyHeaderSize + ext;
    for (int k = 0; k < 6; ++k) {
        const std::size_t n = static_cast<std::size_t>(l.bytes[k]);
        block(p, k)->assign(bytes.begin() + at, bytes.begin() + at + n);
        at += n;
    }
    return p;
}

std::vector<std::uint8_t> gzip(const std::vector<std::uint8_t>& in) {
    z_stream z{};
    if (deflateInit2(&z, Z_DEFAULT_COMPRESSION, Z_DEFLATED, 16 + MAX_WBITS, 9, Z_DEFAULT_STRATEGY) != Z_OK)
        throw IOError("SPZ: cannot initialise zlib");
    std::vector<std::uint8_t> out;
    std::vector<std::uint8_t> buffer(1 << 16);
    z.next_in = const_cast<Bytef*>(in.data());
    std::size_t in_left = in.size();
    int rc = Z_OK;
    InterruptPoll poll;
    while (rc != Z_STREAM_END) {
        if (poll.stop()) {  // one 64 KiB output buffer at a time
            deflateEnd(&z);
            throw Interrupted();
        }
        if (z.avail_in == 0 && in_left) {  // zlib counts in uInt: feed the input in slices
            const std::size_t n = std::min<std::size_t>(in_left, 1u << 30);
            z.avail_in = static_cast<uInt>(n);
            in_left -= n;
        }
        z.next_out = buffer.data();
        z.avail_out = static_cast<uInt>(buffer.size());
        rc = deflate(&z, in_left ? Z_NO_FLUSH : Z_FINISH);
        if (rc != Z_OK && rc != Z_STREAM_END && rc != Z_BUF_ERROR) {
            deflateEnd(&z);
            throw IOError("SPZ: deflate failed");
        }
        out.insert(out.end(), buffer.data(), buffer.data() + (buffer.size() - z.avail_out));
    }
    deflateEnd(&z);
    return out;
}

// ZSTD level of the written streams: 9 compresses the quantised blocks within a few per cent of
// level 19 at a fraction of the time.
constexpr int kZstdLevel = 9;

// One ZSTD frame of `in` that declares its content size (the reader requires the size the header
// implies), compressed 1 MiB at a time so that the interrupt check is polled between pieces.
std::vector<std::uint8_t> zstd(const std::vector<std::uint8_t>& in) {
    std::unique_ptr<ZSTD_CCtx, decltype(&ZSTD_freeCCtx)> cctx(ZSTD_createCCtx(), &ZSTD_freeCCtx);
    if (!cctx) throw IOError("SPZ: cannot create a ZSTD compressor");
    auto check = [](std::size_t rc) {
        if (ZSTD_isError(rc)) throw IOError(std::string("SPZ: ZSTD compression failed: ") + ZSTD_getErrorName(rc));
        return rc;
    };
    check(ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_compressionLevel, kZstdLevel));
    check(ZSTD_CCtx_setParameter(cctx.get(), ZSTD_c_contentSizeFlag, 1));
    check(ZSTD_CCtx_setPledgedSrcSize(cctx.get(), in.size()));
    std::vector<std::uint8_t> out(ZSTD_compressBound(in.size()));
    ZSTD_outBuffer ob{out.data(), out.size(), 0};
    constexpr std::size_t kPiece = std::size_t(1) << 20;
    InterruptPoll poll;
    std::size_t at = 0;
    for (;;) {
        if (poll.stop()) throw Interrupted();
        const std::size_t piece = std::min(kPiece, in.size() - at);
        const bool last = at + piece == in.size();
        ZSTD_inBuffer ib{in.data() + at, piece, 0};
        std::size_t rc = 0;
        do {
            rc = check(ZSTD_compressStream2(cctx.get(), &ob, &ib, last ? ZSTD_e_end : ZSTD_e_continue));
        } while (ib.pos < ib.size || (last && rc != 0));
        at += piece;
        if (last) break;
    }
    out.resize(ob.pos);
    return out;
}

}  // namespace

int sh_rest_for_degree(int degree) {
    static constexpr int rest[5] = {0, 3, 8, 15, 24};
    return degree >= 0 && degree <= 4 ? rest[degree] : 0;
}

PackedSpz unpack_container(const std::uint8_t* data, std::size_t size, const std::string& name) {
    if (is_gzip(data, size)) return unpack_legacy(data, size, name);
    if (size >= 4 && le32(data) == kMagic) return unpack_v4(data, size, name);
    fail(name, "magic: not an SPZ file (neither a gzip stream nor an \"NGSP\" header)");
}

SpzHeader read_header(const std::uint8_t* data, std::size_t size, const std::string& name) {
    CommonHeader c{};
    if (is_gzip(data, size)) {
        Inflater z(data, size, name);
        std::vector<std::uint8_t> bytes;
        z.read_into(bytes, kLegacyHeaderSize);
        if (bytes.size() < kLegacyHeaderSize) fail(name, "header: the gzip stream is shorter than the 16-byte header");
        c = parse_common(bytes.data(), name);
    } else {
        if (size < kHeaderSize) fail(name, "header: file is shorter than the 32-byte header");
        c = parse_common(data, name);
    }
    SpzHeader h;
    h.version = static_cast<int>(c.version);
    h.count = c.count;
    h.sh_degree = c.sh_degree;
    h.fractional_bits = c.fractional_bits;
    h.antialiased = (c.flags & kFlagAntialiased) != 0;
    return h;
}

std::vector<std::uint8_t> pack_container(const PackedSpz& p) {
    const std::uint8_t flags = p.antialiased ? kFlagAntialiased : 0;
    const std::vector<std::uint8_t>* blocks[6] = {&p.positions, &p.alphas, &p.colors, &p.scales, &p.rotations, &p.sh};
    const int streams = p.sh_degree > 0 ? 6 : 5;
    if (p.version <= 3) {  // v2 differs from v3 only in the rotation block, packed by the caller
        std::vector<std::uint8_t> raw;
        put32(raw, kMagic);
        put32(raw, static_cast<std::uint32_t>(p.version));
        put32(raw, p.count);
        raw.insert(raw.end(), {static_cast<std::uint8_t>(p.sh_degree), static_cast<std::uint8_t>(p.fractional_bits), flags, 0});
        for (int k = 0; k < streams; ++k) raw.insert(raw.end(), blocks[k]->begin(), blocks[k]->end());
        return gzip(raw);
    }
    std::vector<std::vector<std::uint8_t>> compressed(streams);
    for (int k = 0; k < streams; ++k) compressed[k] = zstd(*blocks[k]);
    std::vector<std::uint8_t> out;
    put32(out, kMagic);
    put32(out, 4);
    put32(out, p.count);
    out.insert(out.end(), {static_cast<std::uint8_t>(p.sh_degree), static_cast<std::uint8_t>(p.fractional_bits), flags,
                           static_cast<std::uint8_t>(streams)});
    put32(out, static_cast<std::uint32_t>(kHeaderSize));  // tocByteOffset: no extensions
    out.resize(kHeaderSize, 0);                           // reserved
    for (int k = 0; k < streams; ++k) {
        put64(out, compressed[k].size());
        put64(out, blocks[k]->size());
    }
    for (const auto& c : compressed) out.insert(out.end(), c.begin(), c.end());
    return out;
}

}  // namespace avsplat::io::spz
