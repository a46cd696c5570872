#include "avsplat/core/error.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/splat.h"
#include "avsplat/core/sh.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

using avsplat::GaussianCloud;

namespace {
std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }
}  // namespace

TEST_CASE(".splat records follow the antimatter15 layout byte for byte", "[splat]") {
    GaussianCloud c(2, 1);
    c.means = {1, 2, 3, -1, -2, -3};
    c.scales = {0.1f, 0.1f, 0.1f, 1, 2, 3};  // the second is larger: written first
    c.rotations = {2, 0, 0, 0, 0, 0, 0, -1};
    c.opacities = {1.f, 0.5f};
    c.sh[12 + 0] = float(avsplat::sh::color_to_dc(1.0));
    c.sh[12 + 1] = float(avsplat::sh::color_to_dc(0.0));
    c.sh[12 + 2] = float(avsplat::sh::color_to_dc(0.2));
    avsplat::write_splat(tmp("a.splat"), c);

    std::ifstream in(tmp("a.splat"), std::ios::binary);
    std::vector<unsigned char> b((std::istreambuf_iterator<char>(in)), {});
    REQUIRE(b.size() == 64);
    float f[6];
    std::memcpy(f, b.data(), 24);
    CHECK(f[0] == -1.f);
    CHECK(f[5] == 3.f);
    CHECK(int(b[24]) == 255);
    CHECK(int(b[25]) == 0);
    CHECK(int(b[26]) == 51);   // round(0.2 * 255)
    CHECK(int(b[27]) == 128);  // round(0.5 * 255) = 127.5 -> 128
    CHECK(int(b[28]) == 128);  // w = 0
    CHECK(int(b[31]) == 0);    // z = -1 -> 0
    CHECK(int(b[32 + 28]) == 255);  // first written-second Gaussian: w = 1 -> 256 clamped

    const GaussianCloud back = avsplat::read_splat(tmp("a.splat"));
    REQUIRE(back.size() == 2);
    CHECK(back.sh_degree == 0);
    CHECK(back.mean(0) == c.mean(1));
    CHECK(back.opacities[1] == 1.f);
    CHECK(avsplat::sh::dc_to_color<double>(back.sh[2]) == Approx(51 / 255.0));
    CHECK(back.rotations[3] == -1.f);
    CHECK(back.rotations[4] == Approx(127 / 128.0));
}

TEST_CASE(".splat files of a wrong size raise IOError", "[splat]") {
    std::ofstream(tmp("bad.splat"), std::ios::binary).write("0123456789", 10);
    CHECK_THROWS_AS(avsplat::read_splat(tmp("bad.splat")), avsplat::IOError);
    CHECK_THROWS_WITH(avsplat::read_splat(tmp("bad.splat")), Catch::Contains("multiple of the 32-byte"));
    CHECK_THROWS_AS(avsplat::read_splat(tmp("none.splat")), avsplat::IOError);
    std::vector<char> zero(32, 0);
    zero[28] = zero[29] = zero[30] = zero[31] = char(128);
    std::ofstream(tmp("zero.splat"), std::ios::binary).write(zero.data(), 32);
    CHECK_THROWS_WITH(avsplat::read_splat(tmp("zero.splat")), Catch::Contains("record 0"));
}

#include "avsplat/io/gaussian_io.h"

TEST_CASE("read_gaussians and write_gaussians dispatch on the extension", "[splat][gaussian_io]") {
    CHECK(avsplat::file_extension("a/b.c/scene.SPLAT") == ".splat");
    CHECK(avsplat::file_extension("a.b/noext") == "");
    GaussianCloud c(3, 0);
    c.means = {1, 2, 3, 4, 5, 6, 7, 8, 9};
    avsplat::write_gaussians(tmp("d.ply"), c);
    avsplat::write_gaussians(tmp("d.SPLAT"), c);
    CHECK(avsplat::read_gaussians(tmp("d.ply")).means == c.means);
    CHECK(avsplat::read_gaussians(tmp("d.SPLAT")).size() == 3);
    CHECK_THROWS_WITH(avsplat::write_gaussians(tmp("d.obj"), c), Catch::Contains("unsupported extension '.obj'"));
    CHECK_THROWS_AS(avsplat::read_gaussians(tmp("d.obj")), avsplat::IOError);
}

TEST_CASE("a file of another kind is not read as .splat because of its size", "[splat][gaussian_io]") {
    // 2 MB of JSON brackets: a multiple of 32 bytes, and text.
    {
        std::ofstream out(tmp("brackets.json"), std::ios::binary);
        const std::string half(1 << 20, '[');
        out << half << std::string(1 << 20, ']');
    }
    CHECK_THROWS_WITH(avsplat::read_gaussians(tmp("brackets.json")),
                      Catch::Contains("brackets.json") && Catch::Contains("not .splat records"));
    // Binary records whose positions are not plausible (float bit patterns near 1e30).
    {
        std::ofstream out(tmp("noise.bin"), std::ios::binary);
        for (int r = 0; r < 100; ++r) {
            const float v[8] = {1e30f, 2e30f, -3e30f, 0.1f, 0.1f, 0.1f, 0.f, 0.f};
            out.write(reinterpret_cast<const char*>(v), sizeof v);
        }
    }
    CHECK_THROWS_AS(avsplat::read_gaussians(tmp("noise.bin")), avsplat::IOError);
    // A real .splat renamed is still found by its content, and named .splat the checks do not apply.
    GaussianCloud c(64, 0);
    for (std::size_t i = 0; i < c.means.size(); ++i) c.means[i] = float(i) * 0.25f - 3.f;
    avsplat::write_gaussians(tmp("renamed.splat"), c);
    std::filesystem::copy_file(tmp("renamed.splat"), tmp("renamed.bin"),
                               std::filesystem::copy_options::overwrite_existing);
    CHECK(avsplat::read_gaussians(tmp("renamed.bin")).size() == 64);
    std::filesystem::copy_file(tmp("noise.bin"), tmp("noise.splat"), std::filesystem::copy_options::overwrite_existing);
    CHECK(avsplat::read_gaussians(tmp("noise.splat")).size() == 100);
}
