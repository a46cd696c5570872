// The .glb and .ksplat readers through the C++ API: a glb round trip is exact and turns the
// axes by 180 degrees about z in the file; a one-section .ksplat of compression level 0 built
// here byte by byte decodes to its hand-computed values. (tests/python/test_glb.py and
// test_ksplat.py hold both to splat-transform 3.7 and to the other encodings.)
#include "avsplat/core/error.h"
#include "avsplat/core/sh.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/glb.h"
#include "avsplat/io/ksplat.h"

#include <catch2/catch.hpp>

#include <cstring>
#include <fstream>
#include <vector>

using avsplat::GaussianCloud;

namespace {
std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

template <typename T>
void put(std::vector<std::uint8_t>& b, std::size_t at, T v) {
    std::memcpy(&b[at], &v, sizeof v);
}
}  // namespace

TEST_CASE(".glb round trip is exact, and the file holds glTF's axes", "[glb]") {
    GaussianCloud c(3, 1);
    for (std::size_t i = 0; i < c.means.size(); ++i) c.means[i] = 0.5f * float(i) - 2.f;
    for (std::size_t i = 0; i < c.scales.size(); ++i) c.scales[i] = 0.01f * float(i + 1);
    for (std::size_t i = 0; i < c.rotations.size(); ++i) c.rotations[i] = 0.1f * float(i + 1);
    c.opacities = {0.1f, 0.5f, 0.9f};
    for (std::size_t i = 0; i < c.sh.size(); ++i) c.sh[i] = 0.03f * float(i) - 0.5f;
    avsplat::write_gaussians(tmp("c.glb"), c);
    CHECK(avsplat::detect_gaussian_format(tmp("c.glb")).format == avsplat::GaussianFormat::Glb);
    const GaussianCloud back = avsplat::read_gaussians(tmp("c.glb"));
    CHECK(back.means == c.means);
    CHECK(back.scales == c.scales);
    CHECK(back.rotations == c.rotations);
    CHECK(back.opacities == c.opacities);
    CHECK(back.sh == c.sh);
    // The first Gaussian's position in the file: (-x, -y, z).
    std::ifstream in(tmp("c.glb"), std::ios::binary);
    const std::vector<std::uint8_t> b((std::istreambuf_iterator<char>(in)), {});
    std::uint32_t json_length;
    std::memcpy(&json_length, &b[12], 4);
    float p[3];
    std::memcpy(p, &b[20 + json_length + 8], 12);  // POSITION is the first buffer view
    CHECK(p[0] == -c.means[0]);
    CHECK(p[1] == -c.means[1]);
    CHECK(p[2] == c.means[2]);
    CHECK_THROWS_AS(avsplat::parse_glb(b.data(), b.size() / 2, "half.glb"), avsplat::IOError);
}

TEST_CASE(".ksplat of compression level 0 decodes to the record's values", "[ksplat]") {
    // One section, one Gaussian, SH degree 0: 4096 + 1024 header bytes, then a 44-byte record.
    std::vector<std::uint8_t> b(4096 + 1024 + 44, 0);
    b[1] = 1;                        // version 0.1
    put<std::uint32_t>(b, 4, 1);     // sections
    put<std::uint32_t>(b, 8, 1);
    put<std::uint32_t>(b, 12, 1);    // capacity
    put<std::uint32_t>(b, 16, 1);    // Gaussians
    put<std::uint32_t>(b, 4096, 1);  // section: Gaussians, capacity
    put<std::uint32_t>(b, 4100, 1);
    const std::size_t r = 4096 + 1024;
    const float record[10] = {1.f, -2.f, 3.f, 0.5f, 0.25f, 2.f, 1.f, 0.f, 0.f, 0.f};  // xyz, scale, w x y z
    std::memcpy(&b[r], record, sizeof record);
    b[r + 40] = 255, b[r + 41] = 0, b[r + 42] = 51, b[r + 43] = 102;
    const GaussianCloud c = avsplat::parse_ksplat(b.data(), b.size(), "one.ksplat");
    REQUIRE(c.size() == 1);
    CHECK(c.means == std::vector<float>{1.f, -2.f, 3.f});
    CHECK(c.scales == std::vector<float>{0.5f, 0.25f, 2.f});
    CHECK(c.rotations == std::vector<float>{1.f, 0.f, 0.f, 0.f});
    CHECK(c.opacities[0] == Approx(0.4).epsilon(1e-7));
    CHECK(c.sh[0] == Approx(avsplat::sh::color_to_dc(1.0)));
    CHECK(c.sh[1] == Approx(avsplat::sh::color_to_dc(0.0)));
    CHECK(c.sh[2] == Approx(avsplat::sh::color_to_dc(0.2)));
    put<std::uint32_t>(b, 16, 2);  // the header now claims a Gaussian the section does not hold
    CHECK_THROWS_WITH(avsplat::parse_ksplat(b.data(), b.size(), "two.ksplat"),
                      Catch::Contains("two.ksplat: splatCount: the header says 2 Gaussians, the sections hold 1"));
}
