// Tests of the private libzip wrapper (lib/src/io/zip_archive.h).
//
// References independent of libzip: archives assembled byte by byte here (stored entries, a
// bitwise CRC-32), raw deflate streams from zlib, and the byte layout of the local header as
// PKWARE's APPNOTE (4.3.7) gives it, read back by hand.
#include "io/zip_archive.h"

#include "avsplat/core/error.h"

#include <catch2/catch.hpp>

#include <zlib.h>

#include <cstdint>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

using avsplat::IOError;
using avsplat::io::write_zip;
using avsplat::io::ZipReader;
using avsplat::io::ZipWriteEntry;
using Catch::Matchers::Contains;

namespace {

using Bytes = std::vector<unsigned char>;

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/zip_" + name; }

Bytes read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream os;
    os << in.rdbuf();
    const std::string s = os.str();
    return Bytes(s.begin(), s.end());
}

Bytes bytes(const std::string& s) { return Bytes(s.begin(), s.end()); }

void put16(Bytes& b, std::uint32_t v) {
    b.push_back(static_cast<unsigned char>(v & 0xff));
    b.push_back(static_cast<unsigned char>((v >> 8) & 0xff));
}
void put32(Bytes& b, std::uint32_t v) {
    put16(b, v & 0xffff);
    put16(b, v >> 16);
}
std::uint32_t le16(const Bytes& b, std::size_t at) { return b[at] | (b[at + 1] << 8); }
std::uint32_t le32(const Bytes& b, std::size_t at) { return le16(b, at) | (le16(b, at + 2) << 16); }

std::uint32_t crc32_reference(const Bytes& data) {
    std::uint32_t crc = 0xffffffffu;
    for (unsigned char byte : data) {
        crc ^= byte;
        for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1u)));
    }
    return ~crc;
}

Bytes raw_deflate(const Bytes& in) {
    z_stream zs{};
    REQUIRE(deflateInit2(&zs, 6, Z_DEFLATED, -MAX_WBITS, 8, Z_DEFAULT_STRATEGY) == Z_OK);
    Bytes out(deflateBound(&zs, static_cast<uLong>(in.size())));
    zs.next_in = const_cast<unsigned char*>(in.data());
    zs.avail_in = static_cast<uInt>(in.size());
    zs.next_out = out.data();
    zs.avail_out = static_cast<uInt>(out.size());
    REQUIRE(deflate(&zs, Z_FINISH) == Z_STREAM_END);
    out.resize(zs.total_out);
    deflateEnd(&zs);
    return out;
}

struct Entry {
    std::string name;
    Bytes body;               // as stored (already deflated for method 8)
    std::uint32_t size = 0;   // declared uncompressed size
    std::uint32_t crc = 0;
    std::uint16_t method = 0;
    std::uint16_t flags = 0;
};

Entry stored(const std::string& name, const Bytes& data) {
    return {name, data, static_cast<std::uint32_t>(data.size()), crc32_reference(data), 0, 0};
}

Entry deflated(const std::string& name, const Bytes& data) {
    return {name, raw_deflate(data), static_cast<std::uint32_t>(data.size()), crc32_reference(data), 8, 0};
}

// A zip archive assembled by hand: local headers and data, central directory, end record.
Bytes archive(const std::vector<Entry>& entries) {
    Bytes out, central;
    for (const Entry& e : entries) {
        const std::uint32_t offset = static_cast<std::uint32_t>(out.size());
        auto header = [&](Bytes& h, bool is_central) {
            put32(h, is_central ? 0x02014b50 : 0x04034b50);
            if (is_central) put16(h, 20);
            put16(h, 20);
            put16(h, e.flags);
            put16(h, e.method);
            put32(h, 0);
            put32(h, e.crc);
            put32(h, static_cast<std::uint32_t>(e.body.size()));
            put32(h, e.size);
            put16(h, static_cast<std::uint32_t>(e.name.size()));
            put16(h, 0);
            if (is_central) {
                put16(h, 0);
                put16(h, 0);
                put16(h, 0);
                put32(h, 0);
                put32(h, offset);
            }
            h.insert(h.end(), e.name.begin(), e.name.end());
        };
        header(out, false);
        out.insert(out.end(), e.body.begin(), e.body.end());
        header(central, true);
    }
    const std::uint32_t cd_offset = static_cast<std::uint32_t>(out.size());
    out.insert(out.end(), central.begin(), central.end());
    put32(out, 0x06054b50);
    put16(out, 0);
    put16(out, 0);
    put16(out, static_cast<std::uint32_t>(entries.size()));
    put16(out, static_cast<std::uint32_t>(entries.size()));
    put32(out, static_cast<std::uint32_t>(central.size()));
    put32(out, cd_offset);
    put16(out, 0);
    return out;
}

template <class F>
std::string io_error(F&& f) {
    try {
        f();
    } catch (const IOError& e) {
        return e.what();
    }
    return "";
}

}  // namespace

TEST_CASE("ZipReader: stored and deflated entries of a hand-made archive, in order, by name", "[zip]") {
    const Bytes text = bytes("The quick brown fox jumps over the lazy dog. The quick brown fox.");
    const Bytes empty;
    const Bytes image = archive({stored("a.txt", text), deflated("dir/b.bin", text), stored("empty", empty)});
    const ZipReader zip = ZipReader::open_memory(image.data(), image.size(), "mem.zip");
    CHECK(zip.what() == "mem.zip");
    REQUIRE(zip.entries().size() == 3);
    CHECK(zip.entries()[0].name == "a.txt");
    CHECK(zip.entries()[0].size == text.size());
    CHECK(zip.entries()[0].compressed_size == text.size());
    CHECK(zip.entries()[1].name == "dir/b.bin");
    CHECK(zip.entries()[1].compressed_size == raw_deflate(text).size());
    CHECK(zip.read(0, text.size()) == text);
    CHECK(zip.read(1, 1 << 20) == text);
    CHECK(zip.read(2, 0).empty());
    CHECK(zip.read_prefix(1, 9) == bytes("The quick"));
    CHECK(zip.read_prefix(0, 1000) == text);  // no more than the entry holds
    zip.verify(1);
    const avsplat::io::ZipEntryInfo* b = zip.find("dir/b.bin");
    REQUIRE(b != nullptr);
    CHECK(zip.index_of(*b) == 1);
    CHECK(zip.find("b.bin") == nullptr);
    CHECK_THROWS_AS(zip.read(3, 10), std::out_of_range);
}

TEST_CASE("ZipReader: repeated names are listed, find gives the first", "[zip]") {
    const Bytes image = archive({stored("x", bytes("first")), stored("y", bytes("-")), stored("x", bytes("second"))});
    const ZipReader zip = ZipReader::open_memory(image.data(), image.size(), "dup.zip");
    REQUIRE(zip.entries().size() == 3);
    const auto* x = zip.find("x");
    REQUIRE(x != nullptr);
    CHECK(zip.index_of(*x) == 0);
    CHECK(zip.read(2, 100) == bytes("second"));
}

TEST_CASE("ZipReader: corrupt and unsupported archives give IOErrors naming the archive and entry", "[zip]") {
    const Bytes text = bytes("0123456789abcdef0123456789abcdef");
    auto open_error = [](const Bytes& image) {
        return io_error([&] { ZipReader::open_memory(image.data(), image.size(), "bad.zip"); });
    };
    auto read_error = [](const Bytes& image, std::uint64_t max = 1 << 20) {
        return io_error([&] {
            const ZipReader zip = ZipReader::open_memory(image.data(), image.size(), "bad.zip");
            zip.read(0, max);
        });
    };
    CHECK_THAT(open_error({}), Contains("bad.zip") && Contains("too short"));
    CHECK_THAT(open_error(Bytes(100, 'x')), Contains("bad.zip: not a zip archive") && Contains("no zip end record"));
    CHECK_THAT(io_error([] { ZipReader::open_file(tmp("missing.zip")); }), Contains("missing.zip: cannot open"));
    CHECK_THAT(io_error([] { ZipReader::open_file(AVSPLAT_TEST_TMP); }), Contains("is a directory"));

    Entry method = stored("m", text);
    method.method = 12;  // bzip2
    CHECK_THAT(read_error(archive({method})), Contains("bad.zip: entry 'm'") && Contains("method 12"));
    Entry encrypted = stored("e", text);
    encrypted.flags = 1;
    CHECK_THAT(read_error(archive({encrypted})), Contains("entry 'e'") && Contains("encrypted"));
    Entry crc = stored("c", text);
    crc.crc ^= 1;
    CHECK_THAT(read_error(archive({crc})), Contains("entry 'c'") && Contains("CRC-32 mismatch"));
    CHECK_THAT(io_error([&] {
                   const Bytes image = archive({crc});
                   ZipReader::open_memory(image.data(), image.size(), "bad.zip").verify(0);
               }),
               Contains("CRC-32 mismatch"));
    Entry sizes = stored("s", text);
    sizes.size += 1;  // a stored entry whose two sizes differ
    CHECK_THAT(open_error(archive({sizes})) + read_error(archive({sizes})), Contains("entry 's'") && Contains("inconsistent"));
    Entry ratio = deflated("r", text);
    ratio.size = static_cast<std::uint32_t>(ratio.body.size() * 2000);  // no deflate stream expands this much
    CHECK_THAT(open_error(archive({ratio})) + read_error(archive({ratio})), Contains("entry 'r'") && Contains("inconsistent"));
    // The central directory's local header offset past the data.
    Bytes offset = archive({stored("o", text)});
    offset[offset.size() - 22 - 1 - 4] = 0x7f;
    CHECK_THAT(open_error(offset), Contains("entry 'o'") && Contains("out of range"));
    // A name that differs between the local header and the central directory.
    Bytes renamed = archive({stored("n", text)});
    renamed[30] = 'q';
    CHECK_THAT(open_error(renamed), Contains("bad.zip") && Contains("disagrees"));
    // Truncated deflate data.
    Entry cut = deflated("t", text);
    cut.body.resize(cut.body.size() / 2);
    CHECK_THAT(read_error(archive({cut})), Contains("entry 't'"));
}

TEST_CASE("ZipReader: reads are bounded by the declared size and the caller's maximum", "[zip]") {
    const Bytes zeros(1 << 20, 0);
    // Honest directory, 1 MiB: a caller that takes at most 4 KiB is refused before inflation.
    const Bytes honest = archive({deflated("z", zeros)});
    const ZipReader zip = ZipReader::open_memory(honest.data(), honest.size(), "bomb.zip");
    CHECK_THAT(io_error([&] { zip.read(0, 4096); }),
               Contains("entry 'z'") && Contains("declares 1048576 bytes, more than the 4096"));
    CHECK(zip.read(0, zeros.size()) == zeros);
    CHECK(zip.read_prefix(0, 10) == Bytes(10, 0));
    // A directory that declares 100 bytes for the same stream: inflation stops there.
    Entry lying = deflated("z", zeros);
    lying.size = 100;
    lying.crc = crc32_reference(Bytes(100, 0));
    const Bytes bomb = archive({lying});
    const ZipReader small = ZipReader::open_memory(bomb.data(), bomb.size(), "bomb.zip");
    CHECK_THAT(io_error([&] { small.read(0, 1 << 30); }), Contains("entry 'z'") && Contains("inflates to more than the 100"));
    CHECK_THAT(io_error([&] { small.verify(0); }), Contains("inflates to more than the 100"));
    // A prefix within the declared size is served (no CRC: the entry is not read to its end).
    CHECK(small.read_prefix(0, 100) == Bytes(100, 0));
}

TEST_CASE("write_zip: numpy-compatible archives, byte-identical for equal input", "[zip]") {
    const Bytes a = bytes("stored entry"), b(5000, 'b');
    const std::vector<ZipWriteEntry> entries = {
        {"a.txt", a.data(), a.size(), false}, {"b.bin", b.data(), b.size(), true}, {"e", nullptr, 0, true}};
    write_zip(tmp("w1.zip"), entries);
    write_zip(tmp("w2.zip"), entries);
    const Bytes file = read_file(tmp("w1.zip"));
    CHECK(file == read_file(tmp("w2.zip")));
    // The first local header, field by field (APPNOTE 4.3.7).
    REQUIRE(file.size() > 30 + 5 + a.size());
    CHECK(le32(file, 0) == 0x04034b50u);
    CHECK(le16(file, 8) == 0);          // stored
    CHECK(le16(file, 10) == 0);         // time 00:00:00
    CHECK(le16(file, 12) == 0x21);      // date 1980-01-01
    CHECK(le32(file, 14) == crc32_reference(a));
    CHECK(le32(file, 18) == a.size());
    CHECK(le32(file, 22) == a.size());
    CHECK(std::string(file.begin() + 30, file.begin() + 35) == "a.txt");

    const ZipReader zip = ZipReader::open_file(tmp("w1.zip"));
    REQUIRE(zip.entries().size() == 3);
    CHECK(zip.read(0, 100) == a);
    CHECK(zip.entries()[1].compressed_size < b.size());
    CHECK(zip.read(1, b.size()) == b);
    CHECK(zip.read(2, 0).empty());

    CHECK_THROWS_AS(write_zip(tmp("bad.zip"), {{"", a.data(), a.size(), false}}), std::invalid_argument);
    CHECK_THROWS_WITH(write_zip(tmp("bad.zip"), {entries[0], entries[0]}), Contains("'a.txt' repeats"));
    CHECK_THROWS_AS(write_zip(tmp("bad.zip"), {{"n", nullptr, 3, false}}), std::invalid_argument);
    CHECK_THROWS_AS(write_zip(std::string(AVSPLAT_TEST_TMP) + "/no_such_dir/x.zip", entries), IOError);
}

TEST_CASE("write_zip: more than 65,535 entries get zip64 records and read back", "[zip]") {
    const std::size_t n = 70000;
    std::vector<std::string> names(n);
    std::vector<ZipWriteEntry> entries(n);
    const unsigned char byte = 7;
    for (std::size_t k = 0; k < n; ++k) {
        names[k] = "e" + std::to_string(k);
        entries[k] = {names[k], &byte, 1, false};
    }
    write_zip(tmp("many.zip"), entries);
    const Bytes file = read_file(tmp("many.zip"));
    // The zip64 end of central directory locator sits just before the end record.
    REQUIRE(file.size() > 42);
    CHECK(le32(file, file.size() - 22 - 20) == 0x07064b50u);
    const ZipReader zip = ZipReader::open_file(tmp("many.zip"));
    REQUIRE(zip.entries().size() == n);
    const auto* last = zip.find("e69999");
    REQUIRE(last != nullptr);
    CHECK(zip.index_of(*last) == n - 1);
    CHECK(zip.read(n - 1, 1) == Bytes{7});
}
