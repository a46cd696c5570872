#include "avsplat/core/error.h"
#include "avsplat/io/ply_data.h"

#include <catch2/catch.hpp>

#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

void write_bytes(const std::string& path, const std::string& bytes) {
    std::ofstream(path, std::ios::binary) << bytes;
}

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

// A mesh-like file with every scalar type and a list, as a hand-made reference.
avsplat::PlyData sample() {
    using avsplat::PlyType;
    avsplat::PlyData d;
    d.comments = {"made by test_ply_data", ""};
    avsplat::PlyElement v{"vertex", 3, {}};
    const PlyType types[] = {PlyType::Int8, PlyType::UInt8, PlyType::Int16, PlyType::UInt16,
                             PlyType::Int32, PlyType::UInt32, PlyType::Float32, PlyType::Float64};
    const double values[8][3] = {{-128, 0, 127},      {0, 1, 255},        {-32768, 5, 32767},
                                 {0, 7, 65535},       {-2147483648.0, 0, 2147483647.0},
                                 {0, 9, 4294967295.0}, {0.5f, -1e30f, 3.25f}, {1e-300, -0.1, 1e300}};
    for (int k = 0; k < 8; ++k) {
        avsplat::PlyColumn c;
        c.name = "p" + std::to_string(k);
        c.type = types[k];
        c.values.assign(values[k], values[k] + 3);
        v.columns.push_back(c);
    }
    avsplat::PlyElement f{"face", 2, {}};
    avsplat::PlyColumn idx;
    idx.name = "vertex_indices";
    idx.type = PlyType::Int32;
    idx.is_list = true;
    idx.values = {0, 1, 2, 2, 1};
    idx.offsets = {0, 3, 5};
    f.columns.push_back(idx);
    d.elements = {v, f};
    return d;
}

void check_equal(const avsplat::PlyData& a, const avsplat::PlyData& b) {
    REQUIRE(a.elements.size() == b.elements.size());
    for (std::size_t e = 0; e < a.elements.size(); ++e) {
        const auto& x = a.elements[e];
        const auto& y = b.elements[e];
        CHECK(x.name == y.name);
        CHECK(x.count == y.count);
        REQUIRE(x.columns.size() == y.columns.size());
        for (std::size_t c = 0; c < x.columns.size(); ++c) {
            CHECK(x.columns[c].name == y.columns[c].name);
            CHECK(x.columns[c].type == y.columns[c].type);
            CHECK(x.columns[c].is_list == y.columns[c].is_list);
            CHECK(x.columns[c].values == y.columns[c].values);
            CHECK(x.columns[c].offsets == y.columns[c].offsets);
        }
    }
}

}  // namespace

TEST_CASE("PLY columns round-trip every type and lists exactly", "[ply][ply_data]") {
    const avsplat::PlyData d = sample();
    const std::string path = tmp("columns.ply");
    avsplat::write_ply_data(path, d);
    const avsplat::PlyData back = avsplat::read_ply_data(path);
    CHECK(back.format == avsplat::PlyFormat::BinaryLittleEndian);
    CHECK(back.comments == d.comments);
    check_equal(back, d);
    REQUIRE(back.find("face") != nullptr);
    CHECK(back.find("face")->find("vertex_indices")->offsets == std::vector<std::uint64_t>{0, 3, 5});
    CHECK(back.find("edge") == nullptr);

    // The same file image parsed from memory.
    const std::string bytes = slurp(path);
    check_equal(avsplat::parse_ply_data(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), "mem"), d);
}

TEST_CASE("PLY columns: ASCII and big endian files read the same values", "[ply][ply_data]") {
    const std::string header_tail =
        "element vertex 2\nproperty uchar a\nproperty float b\nelement face 1\n"
        "property list uchar int vertex_indices\nend_header\n";
    write_bytes(tmp("cols_ascii.ply"), "ply\nformat ascii 1.0\n" + header_tail + "7 0.5\n255 -2\n3 0 1 2\n");
    std::string be = "ply\nformat binary_big_endian 1.0\n" + header_tail;
    const unsigned char rows[] = {7, 0x3f, 0x00, 0x00, 0x00, 255, 0xc0, 0x00, 0x00, 0x00,
                                  3, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 2};
    be.append(reinterpret_cast<const char*>(rows), sizeof rows);
    write_bytes(tmp("cols_be.ply"), be);
    for (const char* name : {"cols_ascii.ply", "cols_be.ply"}) {
        const avsplat::PlyData d = avsplat::read_ply_data(tmp(name));
        CHECK(d.find("vertex")->find("a")->values == std::vector<double>{7, 255});
        CHECK(d.find("vertex")->find("b")->values == std::vector<double>{0.5, -2});
        CHECK(d.find("face")->find("vertex_indices")->values == std::vector<double>{0, 1, 2});
    }
}

TEST_CASE("PLY columns: malformed files give IOError naming the file", "[ply][ply_data]") {
    avsplat::write_ply_data(tmp("good.ply"), sample());
    const std::string good = slurp(tmp("good.ply"));
    const std::size_t body = good.find("end_header\n") + 11;
    struct Case { const char* name; std::string bytes; const char* message; };
    std::string lying = good;
    lying.replace(lying.find("element face 2"), 14, "element face 9");
    std::string huge_list = good;
    huge_list[good.size() - 4 * 2 - 1] = char(200);  // the second face claims 200 items
    const Case cases[] = {
        {"trunc.ply", good.substr(0, good.size() - 3), "truncated file"},
        {"lying.ply", lying, "truncated file"},
        {"hugelist.ply", huge_list, "truncated file"},
        {"extra.ply", good + "xx", "data after the last element"},
        {"noheader.ply", good.substr(0, body - 11), "header ends before end_header"},
        {"empty.ply", "", "empty file"},
    };
    for (const Case& c : cases) {
        const std::string path = tmp(std::string("pd_") + c.name);
        write_bytes(path, c.bytes);
        CHECK_THROWS_WITH(avsplat::read_ply_data(path), Catch::StartsWith(path + ": ") && Catch::Contains(c.message));
    }
    write_bytes(tmp("pd_ascii_short.ply"), "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int v\nend_header\n3 0 1\n");
    CHECK_THROWS_WITH(avsplat::read_ply_data(tmp("pd_ascii_short.ply")), Catch::Contains("fewer items than its count"));
}

TEST_CASE("PLY columns: a header of 99,000 properties parses", "[ply][ply_data][hostile]") {
    // Duplicate-name checks were quadratic in the number of properties (20 s for this header).
    std::string h = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n";
    for (int k = 0; k < 99000; ++k) h += "property uchar p" + std::to_string(k) + "\n";
    h += "end_header\n" + std::string(99000, '\1');
    write_bytes(tmp("wide.ply"), h);
    const avsplat::PlyData d = avsplat::read_ply_data(tmp("wide.ply"));
    REQUIRE(d.elements.at(0).columns.size() == 99000);
    CHECK(d.elements[0].columns[98999].values == std::vector<double>{1});
    std::string dup = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float a\nproperty float a\nend_header\n";
    write_bytes(tmp("dup.ply"), dup);
    CHECK_THROWS_WITH(avsplat::read_ply_data(tmp("dup.ply")), Catch::Contains("duplicate property \"a\""));
}

TEST_CASE("write_ply_data refuses values that do not fit and leaves the file", "[ply][ply_data]") {
    const std::string path = tmp("refuse.ply");
    avsplat::write_ply_data(path, sample());
    const std::string before = slurp(path);
    avsplat::PlyData bad = sample();
    bad.elements[0].columns[1].values[2] = 256;  // uchar
    CHECK_THROWS_WITH(avsplat::write_ply_data(path, bad), Catch::Contains("property \"p1\" row 2") && Catch::Contains("uchar"));
    bad = sample();
    bad.elements[0].columns[0].values.pop_back();
    CHECK_THROWS_WITH(avsplat::write_ply_data(path, bad), Catch::Contains("2 values for 3 rows"));
    bad = sample();
    bad.elements[0].columns[0].name = "two words";
    CHECK_THROWS_AS(avsplat::write_ply_data(path, bad), std::invalid_argument);
    CHECK(slurp(path) == before);
}
