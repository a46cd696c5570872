// Tests of the .npy / .npz reader and writer (io/npz.h).
//
// References are independent of lib/src/io/npz.cpp: two archives written by numpy 1.24
// (np.savez, whose local headers carry zip64 extra fields, and np.savez_compressed) embedded as
// bytes; .npy images and zip archives (stored entries, optional zip64 records, a bitwise CRC-32)
// assembled byte by byte in this file; expected values written out by hand. Corrupt files are
// made from valid ones by truncating them at every length and by flipping every byte, and must
// give avsplat::IOError, never a crash or a wrong array.
#include "avsplat/io/npz.h"

#include "avsplat/core/error.h"

#include <catch2/catch.hpp>

#include <sys/resource.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

using avsplat::IOError;
using avsplat::NpyArray;
using avsplat::NpyType;
using avsplat::NpzCompression;
using avsplat::read_npz;
using avsplat::write_npz;
using Catch::Matchers::Contains;

namespace {

// np.savez(f, a=np.arange(6, dtype='<f4').reshape(2, 3), m=np.array([True, False, True]))
// np.savez_compressed(f, x=np.linspace(-1, 1, 12).reshape(3, 4), i=np.arange(-3, 3, dtype='>i2'))
const unsigned char kNpStored[] = {
    0x50, 0x4b, 0x03, 0x04, 0x14, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x21, 0x00, 0x4f, 0xe9,
    0x00, 0x2a, 0x98, 0x00, 0x00, 0x00, 0x98, 0x00, 0x00, 0x00, 0x05, 0x00, 0x14, 0x00, 0x61, 0x2e,
    0x6e, 0x70, 0x79, 0x01, 0x00, 0x10, 0x00, 0x98, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x98,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x93, 0x4e, 0x55, 0x4d, 0x50, 0x59, 0x01, 0x00, 0x76,
    0x00, 0x7b, 0x27, 0x64, 0x65, 0x73, 0x63, 0x72, 0x27, 0x3a, 0x20, 0x27, 0x3c, 0x66, 0x34, 0x27,
    0x2c, 0x20, 0x27, 0x66, 0x6f, 0x72, 0x74, 0x72, 0x61, 0x6e, 0x5f, 0x6f, 0x72, 0x64, 0x65, 0x72,
    0x27, 0x3a, 0x20, 0x46, 0x61, 0x6c, 0x73, 0x65, 0x2c, 0x20, 0x27, 0x73, 0x68, 0x61, 0x70, 0x65,
    0x27, 0x3a, 0x20, 0x28, 0x32, 0x2c, 0x20, 0x33, 0x29, 0x2c, 0x20, 0x7d, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x0a, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00,
    0x00, 0x00, 0x40, 0x00, 0x00, 0x40, 0x40, 0x00, 0x00, 0x80, 0x40, 0x00, 0x00, 0xa0, 0x40, 0x50,
    0x4b, 0x03, 0x04, 0x14, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x21, 0x00, 0x16, 0x93, 0x8c,
    0xbb, 0x83, 0x00, 0x00, 0x00, 0x83, 0x00, 0x00, 0x00, 0x05, 0x00, 0x14, 0x00, 0x6d, 0x2e, 0x6e,
    0x70, 0x79, 0x01, 0x00, 0x10, 0x00, 0x83, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x83, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x93, 0x4e, 0x55, 0x4d, 0x50, 0x59, 0x01, 0x00, 0x76, 0x00,
    0x7b, 0x27, 0x64, 0x65, 0x73, 0x63, 0x72, 0x27, 0x3a, 0x20, 0x27, 0x7c, 0x62, 0x31, 0x27, 0x2c,
    0x20, 0x27, 0x66, 0x6f, 0x72, 0x74, 0x72, 0x61, 0x6e, 0x5f, 0x6f, 0x72, 0x64, 0x65, 0x72, 0x27,
    0x3a, 0x20, 0x46, 0x61, 0x6c, 0x73, 0x65, 0x2c, 0x20, 0x27, 0x73, 0x68, 0x61, 0x70, 0x65, 0x27,
    0x3a, 0x20, 0x28, 0x33, 0x2c, 0x29, 0x2c, 0x20, 0x7d, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20, 0x20,
    0x20, 0x20, 0x20, 0x20, 0x20, 0x0a, 0x01, 0x00, 0x01, 0x50, 0x4b, 0x01, 0x02, 0x14, 0x03, 0x14,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x21, 0x00, 0x4f, 0xe9, 0x00, 0x2a, 0x98, 0x00, 0x00,
    0x00, 0x98, 0x00, 0x00, 0x00, 0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x80, 0x01, 0x00, 0x00, 0x00, 0x00, 0x61, 0x2e, 0x6e, 0x70, 0x79, 0x50, 0x4b, 0x01, 0x02,
    0x14, 0x03, 0x14, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x21, 0x00, 0x16, 0x93, 0x8c, 0xbb,
    0x83, 0x00, 0x00, 0x00, 0x83, 0x00, 0x00, 0x00, 0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x80, 0x01, 0xcf, 0x00, 0x00, 0x00, 0x6d, 0x2e, 0x6e, 0x70, 0x79, 0x50,
    0x4b, 0x05, 0x06, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02, 0x00, 0x66, 0x00, 0x00, 0x00, 0x89,
    0x01, 0x00, 0x00, 0x00, 0x00,
};
const unsigned char kNpDeflated[] = {
    0x50, 0x4b, 0x03, 0x04, 0x14, 0x00, 0x00, 0x00, 0x08, 0x00, 0x00, 0x00, 0x21, 0x00, 0xe6, 0x20,
    0x31, 0x8a, 0x7e, 0x00, 0x00, 0x00, 0xe0, 0x00, 0x00, 0x00, 0x05, 0x00, 0x14, 0x00, 0x78, 0x2e,
    0x6e, 0x70, 0x79, 0x01, 0x00, 0x10, 0x00, 0xe0, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x7e,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x9b, 0xec, 0x17, 0xea, 0x1b, 0x10, 0xc9, 0xc8, 0x50,
    0xc6, 0x50, 0xad, 0x9e, 0x92, 0x5a, 0x9c, 0x5c, 0xa4, 0x6e, 0xa5, 0xa0, 0x6e, 0x93, 0x66, 0xa1,
    0xae, 0xa3, 0xa0, 0x9e, 0x96, 0x5f, 0x54, 0x52, 0x94, 0x98, 0x17, 0x9f, 0x5f, 0x94, 0x92, 0x0a,
    0x12, 0x77, 0x4b, 0xcc, 0x29, 0x4e, 0x05, 0x8a, 0x17, 0x67, 0x24, 0x16, 0xa4, 0x02, 0xf9, 0x1a,
    0xc6, 0x3a, 0x0a, 0x26, 0x9a, 0x3a, 0x0a, 0xb5, 0x0a, 0x64, 0x03, 0x2e, 0x06, 0x30, 0xf8, 0xb0,
    0x5f, 0x6f, 0xd7, 0x8b, 0x45, 0xdd, 0x7a, 0xaf, 0xf6, 0xc7, 0x96, 0x5c, 0x74, 0x15, 0x8f, 0x7d,
    0xb2, 0x5f, 0x02, 0xcc, 0xb8, 0xbb, 0x1f, 0xcc, 0x2d, 0xb9, 0xb8, 0xdf, 0x01, 0x44, 0xba, 0x6e,
    0x87, 0xd1, 0xf6, 0x50, 0x71, 0x7b, 0xa8, 0x3a, 0xfb, 0x38, 0x88, 0x3e, 0x7b, 0x03, 0x88, 0x39,
    0xf6, 0x50, 0x73, 0xed, 0x01, 0x50, 0x4b, 0x03, 0x04, 0x14, 0x00, 0x00, 0x00, 0x08, 0x00, 0x00,
    0x00, 0x21, 0x00, 0x6a, 0xd7, 0xfb, 0x65, 0x51, 0x00, 0x00, 0x00, 0x8c, 0x00, 0x00, 0x00, 0x05,
    0x00, 0x14, 0x00, 0x69, 0x2e, 0x6e, 0x70, 0x79, 0x01, 0x00, 0x10, 0x00, 0x8c, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x51, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x9b, 0xec, 0x17, 0xea,
    0x1b, 0x10, 0xc9, 0xc8, 0x50, 0xc6, 0x50, 0xad, 0x9e, 0x92, 0x5a, 0x9c, 0x5c, 0xa4, 0x6e, 0xa5,
    0xa0, 0x6e, 0x97, 0x69, 0xa4, 0xae, 0xa3, 0xa0, 0x9e, 0x96, 0x5f, 0x54, 0x52, 0x94, 0x98, 0x17,
    0x9f, 0x5f, 0x94, 0x92, 0x0a, 0x12, 0x77, 0x4b, 0xcc, 0x29, 0x4e, 0x05, 0x8a, 0x17, 0x67, 0x24,
    0x16, 0xa4, 0x02, 0xf9, 0x1a, 0x66, 0x3a, 0x9a, 0x3a, 0x0a, 0xb5, 0x0a, 0x14, 0x00, 0xae, 0xff,
    0x7f, 0xff, 0xff, 0xfb, 0xff, 0x9f, 0x81, 0x81, 0x81, 0x91, 0x81, 0x09, 0x00, 0x50, 0x4b, 0x01,
    0x02, 0x14, 0x03, 0x14, 0x00, 0x00, 0x00, 0x08, 0x00, 0x00, 0x00, 0x21, 0x00, 0xe6, 0x20, 0x31,
    0x8a, 0x7e, 0x00, 0x00, 0x00, 0xe0, 0x00, 0x00, 0x00, 0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x01, 0x00, 0x00, 0x00, 0x00, 0x78, 0x2e, 0x6e, 0x70, 0x79,
    0x50, 0x4b, 0x01, 0x02, 0x14, 0x03, 0x14, 0x00, 0x00, 0x00, 0x08, 0x00, 0x00, 0x00, 0x21, 0x00,
    0x6a, 0xd7, 0xfb, 0x65, 0x51, 0x00, 0x00, 0x00, 0x8c, 0x00, 0x00, 0x00, 0x05, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x01, 0xb5, 0x00, 0x00, 0x00, 0x69, 0x2e,
    0x6e, 0x70, 0x79, 0x50, 0x4b, 0x05, 0x06, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x02, 0x00, 0x66,
    0x00, 0x00, 0x00, 0x3d, 0x01, 0x00, 0x00, 0x00, 0x00,
};

using Bytes = std::vector<unsigned char>;

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/npz_" + name; }

void write_file(const std::string& path, const Bytes& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    REQUIRE(out.good());
}

Bytes read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream os;
    os << in.rdbuf();
    const std::string s = os.str();
    return Bytes(s.begin(), s.end());
}

Bytes bytes_of(const unsigned char* data, std::size_t n) { return Bytes(data, data + n); }

void put16(Bytes& b, std::uint32_t v) {
    b.push_back(static_cast<unsigned char>(v & 0xff));
    b.push_back(static_cast<unsigned char>((v >> 8) & 0xff));
}
void put32(Bytes& b, std::uint32_t v) {
    put16(b, v & 0xffff);
    put16(b, v >> 16);
}
void put64(Bytes& b, std::uint64_t v) {
    put32(b, static_cast<std::uint32_t>(v));
    put32(b, static_cast<std::uint32_t>(v >> 32));
}
void append(Bytes& b, const std::string& s) { b.insert(b.end(), s.begin(), s.end()); }
void append(Bytes& b, const Bytes& s) { b.insert(b.end(), s.begin(), s.end()); }

// Bitwise CRC-32 (IEEE 802.3, reflected, as zip uses), the reference for zlib's table version.
std::uint32_t crc32_reference(const Bytes& data) {
    std::uint32_t crc = 0xffffffffu;
    for (unsigned char byte : data) {
        crc ^= byte;
        for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
    }
    return ~crc;
}

// A .npy image: magic, version, header length (2 bytes for 1.0, 4 for 2.0 and 3.0), the dict
// padded with spaces and a newline, then the data.
Bytes npy(const std::string& dict, const Bytes& data, int major = 1) {
    Bytes b = {0x93, 'N', 'U', 'M', 'P', 'Y', static_cast<unsigned char>(major), 0};
    const std::size_t prefix = major == 1 ? 10 : 12;
    std::string header = dict;
    while ((prefix + header.size() + 1) % 64 != 0) header += ' ';
    header += '\n';
    if (major == 1) put16(b, static_cast<std::uint32_t>(header.size()));
    else put32(b, static_cast<std::uint32_t>(header.size()));
    append(b, header);
    append(b, data);
    return b;
}

template <class T>
Bytes raw(const std::vector<T>& v, bool big_endian = false) {
    Bytes b(v.size() * sizeof(T));
    std::memcpy(b.data(), v.data(), b.size());
    if (big_endian)
        for (std::size_t i = 0; i < v.size(); ++i)
            for (std::size_t k = 0; k < sizeof(T) / 2; ++k)
                std::swap(b[i * sizeof(T) + k], b[i * sizeof(T) + sizeof(T) - 1 - k]);
    return b;
}

struct Entry {
    std::string name;
    Bytes data;
    std::uint16_t method = 0;  // written stored whatever this says (to test unsupported methods)
    std::uint16_t flags = 0;
};

// A zip archive of stored entries, assembled here. zip64: sizes and offsets in the central
// directory are 0xffffffff with a zip64 extra field, and a zip64 end record + locator precede
// the (saturated) end record, as zip tools write archives over 4 GiB.
Bytes zip(const std::vector<Entry>& entries, bool zip64 = false, const std::string& comment = "") {
    Bytes out, central;
    for (const Entry& e : entries) {
        const std::uint64_t offset = out.size();
        const std::uint32_t crc = crc32_reference(e.data);
        put32(out, 0x04034b50);
        put16(out, 20);
        put16(out, e.flags);
        put16(out, e.method);
        put32(out, 0);
        put32(out, crc);
        put32(out, static_cast<std::uint32_t>(e.data.size()));
        put32(out, static_cast<std::uint32_t>(e.data.size()));
        put16(out, static_cast<std::uint32_t>(e.name.size()));
        put16(out, 0);
        append(out, e.name);
        append(out, e.data);

        put32(central, 0x02014b50);
        put16(central, 45);
        put16(central, 45);
        put16(central, e.flags);
        put16(central, e.method);
        put32(central, 0);
        put32(central, crc);
        put32(central, zip64 ? 0xffffffffu : static_cast<std::uint32_t>(e.data.size()));
        put32(central, zip64 ? 0xffffffffu : static_cast<std::uint32_t>(e.data.size()));
        put16(central, static_cast<std::uint32_t>(e.name.size()));
        put16(central, zip64 ? 28 : 0);
        put16(central, 0);
        put16(central, 0);
        put16(central, 0);
        put32(central, 0);
        put32(central, zip64 ? 0xffffffffu : static_cast<std::uint32_t>(offset));
        append(central, e.name);
        if (zip64) {
            put16(central, 1);
            put16(central, 24);
            put64(central, e.data.size());  // uncompressed
            put64(central, e.data.size());  // compressed
            put64(central, offset);
        }
    }
    const std::uint64_t cd_offset = out.size();
    append(out, central);
    if (zip64) {
        const std::uint64_t record = out.size();
        put32(out, 0x06064b50);
        put64(out, 44);
        put16(out, 45);
        put16(out, 45);
        put32(out, 0);
        put32(out, 0);
        put64(out, entries.size());
        put64(out, entries.size());
        put64(out, central.size());
        put64(out, cd_offset);
        put32(out, 0x07064b50);
        put32(out, 0);
        put64(out, record);
        put32(out, 1);
    }
    put32(out, 0x06054b50);
    put16(out, 0);
    put16(out, 0);
    put16(out, zip64 ? 0xffff : static_cast<std::uint32_t>(entries.size()));
    put16(out, zip64 ? 0xffff : static_cast<std::uint32_t>(entries.size()));
    put32(out, zip64 ? 0xffffffffu : static_cast<std::uint32_t>(central.size()));
    put32(out, zip64 ? 0xffffffffu : static_cast<std::uint32_t>(cd_offset));
    put16(out, static_cast<std::uint32_t>(comment.size()));
    append(out, comment);
    return out;
}

std::vector<NpyArray> read_bytes(const Bytes& b, const std::string& name) {
    const std::string path = tmp(name);
    write_file(path, b);
    return read_npz(path);
}

NpyArray parse(const Bytes& b) { return avsplat::parse_npy(b.data(), b.size(), "test.npy", "t"); }

// The message of the IOError that `f` throws ("" when it throws nothing; other exceptions fail).
template <class F>
std::string io_error(F&& f) {
    try {
        f();
    } catch (const IOError& e) {
        return e.what();
    }
    return "";
}

std::string message_of_npz(const Bytes& b, const std::string& name) {
    return io_error([&] { read_bytes(b, name); });
}

}  // namespace

TEST_CASE("npz: archives written by numpy's savez and savez_compressed", "[npz]") {
    const auto stored = read_bytes(bytes_of(kNpStored, sizeof kNpStored), "np_stored.npz");
    REQUIRE(stored.size() == 2);
    CHECK(stored[0].name == "a");
    CHECK(stored[0].type == NpyType::Float32);
    CHECK(stored[0].shape == std::vector<std::size_t>{2, 3});
    CHECK(stored[0].to_float32() == std::vector<float>{0, 1, 2, 3, 4, 5});
    CHECK(stored[1].name == "m");
    CHECK(stored[1].type == NpyType::Bool);
    CHECK(stored[1].shape_string() == "(3,)");
    CHECK(stored[1].bytes == Bytes{1, 0, 1});

    const auto deflated = read_bytes(bytes_of(kNpDeflated, sizeof kNpDeflated), "np_deflated.npz");
    REQUIRE(deflated.size() == 2);
    const NpyArray* x = avsplat::find_array(deflated, "x");
    const NpyArray* i = avsplat::find_array(deflated, "i");
    REQUIRE(x);
    REQUIRE(i);
    CHECK(avsplat::find_array(deflated, "y") == nullptr);
    CHECK(x->type == NpyType::Float64);
    CHECK(x->shape == std::vector<std::size_t>{3, 4});
    const std::vector<double> xv = x->to_float64();
    for (int k = 0; k < 12; ++k) CHECK(xv[static_cast<std::size_t>(k)] == Approx(-1.0 + 2.0 * k / 11.0).margin(1e-15));
    CHECK(i->type == NpyType::Int16);  // stored big endian, read into host order
    CHECK(i->to_float32() == std::vector<float>{-3, -2, -1, 0, 1, 2});
}

TEST_CASE("npz: every type and shape survives write_npz -> read_npz, stored and deflated", "[npz]") {
    const std::vector<float> f = {1.5f, -0.0f, std::numeric_limits<float>::infinity(), 3e-40f, -7.25f, 1e30f};
    const std::vector<double> d = {1.0 / 3.0, -2.5, 1e-300, 6.0};
    const std::vector<std::int64_t> i64 = {-(std::int64_t(1) << 62), 0, 42};
    const std::vector<std::uint8_t> u8 = {0, 255, 7, 8};
    const std::vector<std::int32_t> i32 = {-2147483647 - 1, 2147483647};
    const std::vector<std::uint16_t> u16 = {65535, 1};
    const bool flags[3] = {true, false, true};
    const std::vector<NpyArray> arrays = {
        NpyArray::from_data("f", {2, 3}, f.data()),
        NpyArray::from_data("d", {4}, d.data()),
        NpyArray::from_data("i64", {3, 1}, i64.data()),
        NpyArray::from_data("u8", {2, 2}, u8.data()),
        NpyArray::from_data("i32", {2}, i32.data()),
        NpyArray::from_data("u16", {1, 1, 2}, u16.data()),
        NpyArray::from_data("b", {3}, flags),
        NpyArray::from_data("scalar", {}, d.data()),
        NpyArray::from_data<float>("empty", {0, 3}, nullptr),
    };
    for (auto compression : {NpzCompression::Stored, NpzCompression::Deflated}) {
        const std::string path = tmp(compression == NpzCompression::Stored ? "rt_stored.npz" : "rt_deflated.npz");
        write_npz(path, arrays, compression);
        const auto back = read_npz(path);
        REQUIRE(back.size() == arrays.size());
        for (std::size_t k = 0; k < arrays.size(); ++k) {
            INFO(arrays[k].name);
            CHECK(back[k].name == arrays[k].name);
            CHECK(back[k].type == arrays[k].type);
            CHECK(back[k].shape == arrays[k].shape);
            CHECK(back[k].bytes == arrays[k].bytes);
        }
        CHECK(back[7].size() == 1);
        CHECK(back[7].shape_string() == "()");
        CHECK(back[8].size() == 0);
        // Equal arrays give equal files (fixed timestamps).
        const std::string again = path + ".again";
        write_npz(again, arrays, compression);
        CHECK(read_file(again) == read_file(path));
    }
}

TEST_CASE("npz: archives assembled here, with comments, zip64 records and non-array entries", "[npz]") {
    const Bytes a = npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2,), }", raw<float>({0.5f, -1.0f}));
    const Bytes b = npy("{'descr': '<i4', 'fortran_order': False, 'shape': (), }", raw<std::int32_t>({-9}));
    for (bool zip64 : {false, true}) {
        INFO("zip64 " << zip64);
        const auto arrays = read_bytes(zip({{"a.npy", a}, {"README.txt", {'h', 'i'}}, {"sub/b.npy", b}}, zip64, "a comment"),
                                       "assembled.npz");
        REQUIRE(arrays.size() == 2);  // README.txt is not an array and is skipped
        CHECK(arrays[0].name == "a");
        CHECK(arrays[0].to_float32() == std::vector<float>{0.5f, -1.0f});
        CHECK(arrays[1].name == "sub/b");
        CHECK(arrays[1].to_float64() == std::vector<double>{-9.0});
    }
    // An empty archive (np.savez with no arrays) holds no arrays.
    CHECK(read_bytes(zip({}), "empty.npz").empty());
}

TEST_CASE("npy: header versions, byte orders, float16, Fortran order", "[npz]") {
    SECTION("versions 1.0, 2.0 and 3.0 and Python 2 style shapes") {
        for (int major : {1, 2, 3}) {
            const NpyArray a = parse(npy("{'descr': '<f8', 'fortran_order': False, 'shape': (1L, 2L), }",
                                         raw<double>({2.0, -3.0}), major));
            CHECK(a.shape == std::vector<std::size_t>{1, 2});
            CHECK(a.to_float64() == std::vector<double>{2.0, -3.0});
        }
        // Keys in another order, double quotes, no trailing comma.
        const NpyArray a = parse(npy("{\"shape\": (3,), \"fortran_order\": False, \"descr\": \"|u1\"}", {1, 2, 250}));
        CHECK(a.type == NpyType::UInt8);
        CHECK(a.to_float32() == std::vector<float>{1, 2, 250});
    }
    SECTION("big-endian data is converted to host order") {
        const NpyArray a = parse(npy("{'descr': '>f4', 'fortran_order': False, 'shape': (3,), }",
                                     raw<float>({1.0f, -2.5f, 1e-3f}, true)));
        CHECK(a.to_float32() == std::vector<float>{1.0f, -2.5f, 1e-3f});
        const NpyArray u = parse(npy("{'descr': '>u8', 'fortran_order': False, 'shape': (1,), }",
                                     raw<std::uint64_t>({0x0102030405060708ull}, true)));
        std::uint64_t v;
        std::memcpy(&v, u.bytes.data(), 8);
        CHECK(v == 0x0102030405060708ull);
    }
    SECTION("float16: normal, subnormal, zero, infinity, NaN") {
        // 1.0, -2.0, 65504 (max), 2^-24 (smallest subnormal), 2^-14 (smallest normal), -0, +inf, nan
        const std::vector<std::uint16_t> h = {0x3c00, 0xc000, 0x7bff, 0x0001, 0x0400, 0x8000, 0x7c00, 0x7e00};
        const NpyArray a = parse(npy("{'descr': '<f2', 'fortran_order': False, 'shape': (8,), }", raw(h)));
        const std::vector<float> v = a.to_float32();
        CHECK(v[0] == 1.0f);
        CHECK(v[1] == -2.0f);
        CHECK(v[2] == 65504.0f);
        CHECK(v[3] == std::ldexp(1.0f, -24));
        CHECK(v[4] == std::ldexp(1.0f, -14));
        CHECK(v[5] == 0.0f);
        CHECK(std::signbit(v[5]));
        CHECK(std::isinf(v[6]));
        CHECK(std::isnan(v[7]));
    }
    SECTION("Fortran order is transposed into C order") {
        // Element (i, j, k) of a 2 x 3 x 4 array holds 100 i + 10 j + k; in Fortran order it is
        // stored at i + 2 j + 6 k.
        std::vector<std::int32_t> fortran(24);
        for (int i = 0; i < 2; ++i)
            for (int j = 0; j < 3; ++j)
                for (int k = 0; k < 4; ++k) fortran[static_cast<std::size_t>(i + 2 * j + 6 * k)] = 100 * i + 10 * j + k;
        const NpyArray a = parse(npy("{'descr': '<i4', 'fortran_order': True, 'shape': (2, 3, 4), }", raw(fortran)));
        const std::vector<double> v = a.to_float64();
        for (int i = 0; i < 2; ++i)
            for (int j = 0; j < 3; ++j)
                for (int k = 0; k < 4; ++k) CHECK(v[static_cast<std::size_t>(12 * i + 4 * j + k)] == 100 * i + 10 * j + k);
        // 1-d and 0-d Fortran arrays are already in C order.
        CHECK(parse(npy("{'descr': '<i4', 'fortran_order': True, 'shape': (2,), }", raw<std::int32_t>({5, 6})))
                  .to_float32() == std::vector<float>{5, 6});
    }
    SECTION("conversions to float") {
        CHECK(parse(npy("{'descr': '|b1', 'fortran_order': False, 'shape': (3,), }", {0, 1, 2})).to_float32() ==
              std::vector<float>{0, 1, 1});
        CHECK(parse(npy("{'descr': '|i1', 'fortran_order': False, 'shape': (2,), }", {0xff, 0x80})).to_float32() ==
              std::vector<float>{-1, -128});
        CHECK(parse(npy("{'descr': '<i8', 'fortran_order': False, 'shape': (1,), }", raw<std::int64_t>({-(std::int64_t(1) << 40)})))
                  .to_float64() == std::vector<double>{-1099511627776.0});
        CHECK(parse(npy("{'descr': '<f8', 'fortran_order': False, 'shape': (1,), }", raw<double>({1e300}))).to_float32()[0] ==
              std::numeric_limits<float>::infinity());
    }
}

TEST_CASE("npy: malformed headers and unsupported dtypes name the array and the problem", "[npz]") {
    const Bytes four = raw<float>({1, 2, 3, 4});
    auto message = [](const Bytes& b) { return io_error([&] { parse(b); }); };
    CHECK_THAT(message({'N', 'U', 'M', 'P', 'Y', 1, 0, 0, 0, 0}), Contains("test.npy") && Contains("bad magic"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", four, 4)),
               Contains("version 4.0"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'shape': (4,), }", four)), Contains("missing key 'fortran_order'"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), 'extra': 1}", four)),
               Contains("unexpected key 'extra'"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': 0, 'shape': (4,), }", four)), Contains("fortran_order"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4, -1), }", four)),
               Contains("non-negative integer"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': False, 'shape': [4], }", four)), Contains("not a tuple"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4,) } x", four)),
               Contains("after the dictionary"));
    CHECK_THAT(message(npy("{'descr': [('x', '<f4')], 'fortran_order': False, 'shape': (4,), }", four)),
               Contains("structured"));
    CHECK_THAT(message(npy("{'descr': '|O', 'fortran_order': False, 'shape': (4,), }", four)), Contains("pickled"));
    CHECK_THAT(message(npy("{'descr': '<U1', 'fortran_order': False, 'shape': (4,), }", four)),
               Contains("'<U1' is not supported"));
    CHECK_THAT(message(npy("{'descr': '<c8', 'fortran_order': False, 'shape': (2,), }", four)),
               Contains("'<c8' is not supported"));
    CHECK_THAT(message(npy("{'descr': '<f3', 'fortran_order': False, 'shape': (4,), }", four)), Contains("'<f3'"));
    // Data shorter or longer than the shape says.
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (5,), }", four)),
               Contains("data has 16 bytes") && Contains("needs 20"));
    CHECK_THAT(message(npy("{'descr': '<f4', 'fortran_order': False, 'shape': (3,), }", four)),
               Contains("data has 16 bytes") && Contains("needs 12"));
    // A shape whose byte count overflows size_t.
    CHECK_THAT(message(npy("{'descr': '<f8', 'fortran_order': False, 'shape': (4294967296, 4294967296), }", four)),
               Contains("too large"));
    // Header length past the end.
    Bytes cut = npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", four);
    cut.resize(30);
    CHECK_THAT(message(cut), Contains("truncated .npy header"));
}

TEST_CASE("npz: corrupt and unsupported archives throw IOError naming the file and entry", "[npz]") {
    const Bytes a = npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", raw<float>({1, 2, 3, 4}));
    auto message = [](const Bytes& b, const std::string& name) {
        return io_error([&] { read_bytes(b, name); });
    };
    CHECK_THAT(message({}, "zero.npz"), Contains("npz_zero.npz") && Contains("too short"));
    CHECK_THAT(message(a, "plain_npy.npz"), Contains("no zip end record"));
    CHECK_THAT(io_error([] { read_npz(tmp("does_not_exist.npz")); }), Contains("cannot open"));

    Bytes flipped = zip({{"a.npy", a}});
    flipped[30 + 5 + 70] ^= 0x01;  // a data byte of the .npy entry
    CHECK_THAT(message(flipped, "crc.npz"), Contains("entry 'a.npy'") && Contains("CRC-32 mismatch"));
    CHECK_THAT(message(zip({{"a.npy", a}, {"a.npy", a}}), "dup.npz"), Contains("duplicate array name 'a'"));
    CHECK_THAT(message(zip({{"a.npy", a, 12}}), "bzip2.npz"), Contains("entry 'a.npy'") && Contains("method 12"));
    CHECK_THAT(message(zip({{"a.npy", a, 0, 1}}), "encrypted.npz"), Contains("encrypted"));

    // A stored entry whose sizes disagree, and a local header offset past the data.
    Bytes sizes = zip({{"a.npy", a}});
    const std::size_t cd = 30 + 5 + a.size();
    sizes[cd + 20] ^= 0x01;  // compressed size in the central directory
    CHECK_THAT(message(sizes, "sizes.npz"), Contains("entry 'a.npy'"));
    Bytes offset = zip({{"a.npy", a}});
    offset[cd + 44] = 0x7f;  // local header offset
    CHECK_THAT(message(offset, "offset.npz"), Contains("out of range"));
}

TEST_CASE("npz: every truncation and every single-byte flip gives IOError or the right arrays", "[npz]") {
    // Small archives, so that every byte is tried: numpy's deflated one, and a stored zip64 one.
    const Bytes a = npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2,), }", raw<float>({0.5f, 2.0f}));
    const std::vector<std::pair<std::string, Bytes>> files = {
        {"numpy_deflated", bytes_of(kNpDeflated, sizeof kNpDeflated)},
        {"zip64", zip({{"a.npy", a}}, true)},
    };
    for (const auto& [label, good] : files) {
        INFO(label);
        const auto expected = read_bytes(good, "good.npz");
        for (std::size_t n = 0; n < good.size(); ++n) {
            INFO("truncated to " << n << " bytes");
            CHECK_THROWS_AS(read_bytes(Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n)), "cut.npz"), IOError);
        }
        std::size_t thrown = 0;
        for (std::size_t k = 0; k < good.size(); ++k) {
            Bytes bad = good;
            bad[k] ^= 0x5a;
            INFO("byte " << k << " flipped");
            try {
                const auto arrays = read_bytes(bad, "flip.npz");
                // Bytes the reader does not depend on (timestamps, versions, attributes) may
                // change; the arrays must then be exactly the original ones.
                REQUIRE(arrays.size() == expected.size());
                for (std::size_t i = 0; i < arrays.size(); ++i) {
                    CHECK(arrays[i].name == expected[i].name);
                    CHECK(arrays[i].shape == expected[i].shape);
                    CHECK(arrays[i].bytes == expected[i].bytes);
                }
            } catch (const IOError&) {
                ++thrown;
            }
        }
        CHECK(thrown > good.size() / 2);
    }
}

TEST_CASE("read_npy: a .npy file, named after the file", "[npz]") {
    const std::string path = tmp("single.npy");
    write_file(path, npy("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 1), }", raw<float>({3.0f, 4.0f})));
    const NpyArray a = avsplat::read_npy(path);
    CHECK(a.name == "npz_single");
    CHECK(a.shape == std::vector<std::size_t>{2, 1});
    CHECK(a.to_float32() == std::vector<float>{3.0f, 4.0f});
    CHECK_THAT(io_error([] { avsplat::read_npy(tmp("missing.npy")); }), Contains("cannot open"));
}

TEST_CASE("write_npz: invalid arrays are rejected", "[npz]") {
    const float v[2] = {1, 2};
    NpyArray ok = NpyArray::from_data("v", {2}, v);
    NpyArray unnamed = ok;
    unnamed.name.clear();
    CHECK_THROWS_WITH(write_npz(tmp("bad.npz"), {unnamed}), Contains("arrays[0].name"));
    CHECK_THROWS_WITH(write_npz(tmp("bad.npz"), {ok, ok}), Contains("'v' repeats arrays[0]"));
    NpyArray short_bytes = ok;
    short_bytes.bytes.pop_back();
    CHECK_THROWS_WITH(write_npz(tmp("bad.npz"), {short_bytes}), Contains("7 bytes do not match shape (2,)"));
    CHECK_THROWS_AS(NpyArray::from_data<float>("null", {2}, nullptr), std::invalid_argument);
    CHECK_THROWS_AS(write_npz(std::string(AVSPLAT_TEST_TMP) + "/no_such_dir/x.npz", {ok}), IOError);
}

namespace {

// A deflate stream of `head` followed by `mib` MiB of zero bytes. Each MiB is deflated once
// after a full flush (which resets the history), so its bytes can be repeated: the stream is
// assembled without compressing a GiB. 1 GiB of zeros takes about 1 MB.
Bytes deflate_bomb(const Bytes& head, std::size_t mib) {
    z_stream zs{};
    REQUIRE(deflateInit2(&zs, 9, Z_DEFLATED, -MAX_WBITS, 9, Z_DEFAULT_STRATEGY) == Z_OK);
    Bytes buffer(std::size_t(1) << 21);
    auto run = [&](const unsigned char* data, std::size_t n, int flush) {
        zs.next_in = const_cast<unsigned char*>(data);
        zs.avail_in = static_cast<uInt>(n);
        zs.next_out = buffer.data();
        zs.avail_out = static_cast<uInt>(buffer.size());
        REQUIRE(deflate(&zs, flush) != Z_STREAM_ERROR);
        REQUIRE(zs.avail_in == 0);
        REQUIRE(zs.avail_out > 0);
        return Bytes(buffer.data(), buffer.data() + (buffer.size() - zs.avail_out));
    };
    Bytes out = run(head.data(), head.size(), Z_FULL_FLUSH);
    const Bytes zeros(std::size_t(1) << 20, 0);
    const Bytes block = run(zeros.data(), zeros.size(), Z_FULL_FLUSH);
    for (std::size_t k = 0; k < mib; ++k) out.insert(out.end(), block.begin(), block.end());
    const Bytes end = run(nullptr, 0, Z_FINISH);
    out.insert(out.end(), end.begin(), end.end());
    deflateEnd(&zs);
    return out;
}

// One deflated entry with the sizes and CRC given (not computed), for lying directories.
Bytes deflated_zip(const std::string& name, const Bytes& body, std::uint32_t declared, std::uint32_t crc) {
    Bytes out;
    auto header = [&](Bytes& h, bool central) {
        put32(h, central ? 0x02014b50 : 0x04034b50);
        if (central) put16(h, 20);
        put16(h, 20);
        put16(h, 0);
        put16(h, 8);
        put32(h, 0);
        put32(h, crc);
        put32(h, static_cast<std::uint32_t>(body.size()));
        put32(h, declared);
        put16(h, static_cast<std::uint32_t>(name.size()));
        put16(h, 0);
        if (central) {
            put16(h, 0);
            put16(h, 0);
            put16(h, 0);
            put32(h, 0);
            put32(h, 0);
        }
        append(h, name);
    };
    header(out, false);
    append(out, body);
    Bytes central;
    header(central, true);
    const std::size_t cd_offset = out.size();
    append(out, central);
    put32(out, 0x06054b50);
    put16(out, 0);
    put16(out, 0);
    put16(out, 1);
    put16(out, 1);
    put32(out, static_cast<std::uint32_t>(central.size()));
    put32(out, static_cast<std::uint32_t>(cd_offset));
    put16(out, 0);
    return out;
}

long max_rss_kib() {
    struct rusage usage {};
    getrusage(RUSAGE_SELF, &usage);
    return usage.ru_maxrss;
}

}  // namespace

TEST_CASE("npz: a 1 MB deflate bomb gives a clear IOError without inflating it", "[npz]") {
    // The .npy header says 4 float32 (16 bytes of data); the stream goes on with 1 GiB of zeros.
    const Bytes head = npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", raw<float>({1, 2, 3, 4}));
    const std::uint64_t zeros = std::uint64_t(1) << 30;
    const Bytes body = deflate_bomb(head, 1024);
    REQUIRE(body.size() < (std::size_t(3) << 20));  // about 1 MB on disk
    const long before = max_rss_kib();
    // Peak memory may not grow by more than a small multiple of the file: nothing near 1 GiB.
    auto bounded = [&] { CHECK(max_rss_kib() - before < 64 * 1024); };

    SECTION("the directory declares the true 1 GiB: refused before inflating, from the .npy header") {
        const std::uint32_t declared = static_cast<std::uint32_t>(head.size() + zeros);
        CHECK_THAT(message_of_npz(deflated_zip("a.npy", body, declared, 0), "bomb_honest.npz"),
                   Contains("entry 'a.npy'") && Contains("declares " + std::to_string(declared)) &&
                       Contains("its .npy header describes"));
        bounded();
    }
    SECTION("the directory declares the .npy size: inflation stops there") {
        CHECK_THAT(message_of_npz(deflated_zip("a.npy", body, static_cast<std::uint32_t>(head.size()), 0), "bomb_small.npz"),
                   Contains("entry 'a.npy'") && Contains("inflates to more than the " + std::to_string(head.size())));
        bounded();
    }
}

TEST_CASE("npz: 60,000 arrays read back in order, and a repeated name among them is named", "[npz]") {
    // The duplicate check is a hash lookup (it was a linear scan per entry: 60,000 entries took 7 s).
    const std::size_t n = 60000;
    std::vector<NpyArray> arrays;
    arrays.reserve(n);
    for (std::size_t k = 0; k < n; ++k) {
        const std::int32_t v = static_cast<std::int32_t>(k);
        arrays.push_back(NpyArray::from_data("a" + std::to_string(k), {1}, &v));
    }
    const std::string path = tmp("many.npz");
    write_npz(path, arrays);
    const std::vector<NpyArray> back = read_npz(path);
    REQUIRE(back.size() == n);
    for (std::size_t k = 0; k < n; k += 997) {
        CHECK(back[k].name == "a" + std::to_string(k));
        CHECK(back[k].to_float64() == std::vector<double>{double(k)});
    }
    CHECK(back.back().name == "a" + std::to_string(n - 1));

    // The same names, the last one repeating the first: the stored archive is assembled by hand
    // (write_npz refuses duplicates).
    const Bytes one = npy("{'descr': '<f4', 'fortran_order': False, 'shape': (), }", raw<float>({1}));
    std::vector<Entry> entries;
    entries.reserve(n);
    for (std::size_t k = 0; k + 1 < n; ++k) entries.push_back({"a" + std::to_string(k) + ".npy", one});
    entries.push_back({"a0.npy", one});
    CHECK_THAT(message_of_npz(zip(entries, true), "many_dup.npz"),
               Contains("entry 'a0.npy'") && Contains("duplicate array name 'a0'"));
}
