// SPZ: quantisation bounds of a round trip, the bytes of a hand-computed Gaussian, the axis
// change against brute-force SH evaluation, and hostile files (truncations, bit flips, lying
// sizes, decompression bombs). Version 2 files and splat-transform's files are tested from
// Python (tests/python/test_spz.py).
#include "avsplat/core/error.h"
#include "avsplat/core/sh.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/spz.h"
#include "io/spz/spz_attributes.h"
#include "io/spz/spz_container.h"

#include <catch2/catch.hpp>
#include <zstd.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstring>
#include <fstream>
#include <random>

using avsplat::GaussianCloud;
using avsplat::SpzCoordinateSystem;
namespace spz = avsplat::io::spz;

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

std::vector<std::uint8_t> file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::vector<std::uint8_t>((std::istreambuf_iterator<char>(in)), {});
}

void put_file(const std::string& path, const std::vector<std::uint8_t>& b) {
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
}

// A random cloud inside the ranges SPZ represents: |x| < 100, log scales in [-9, 5], opacity in
// [0, 1], DC in [-3, 3], higher SH in [-0.95, 0.95].
GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = 100.f * u(rng);
    for (auto& v : c.scales) v = std::exp(-2.f + 7.f * u(rng));
    for (auto& v : c.rotations) v = u(rng);
    for (auto& v : c.opacities) v = 0.5f + 0.5f * u(rng);
    const int k = c.sh_coeffs();
    for (std::size_t i = 0; i < n; ++i)
        for (int j = 0; j < k; ++j)
            for (int ch = 0; ch < 3; ++ch) c.sh[(i * k + j) * 3 + ch] = (j == 0 ? 3.f : 0.95f) * u(rng);
    return c;
}

Eigen::Matrix3d rotation_matrix(const float* q) {
    return Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
}

// Checks `back` against `c` within SPZ's quantisation (fractional bits 12).
void check_within_quantisation(const GaussianCloud& c, const GaussianCloud& back) {
    REQUIRE(back.size() == c.size());
    REQUIRE(back.sh_degree == c.sh_degree);
    const int k = c.sh_coeffs();
    double pos = 0, logscale = 0, rot = 0, alpha = 0, dc = 0, band1 = 0, rest = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
        for (int t = 0; t < 3; ++t) {
            pos = std::max(pos, std::fabs(double(back.means[3 * i + t]) - c.means[3 * i + t]));
            logscale = std::max(logscale, std::fabs(std::log(double(back.scales[3 * i + t])) - std::log(double(c.scales[3 * i + t]))));
        }
        rot = std::max(rot, (rotation_matrix(&back.rotations[4 * i]) - rotation_matrix(&c.rotations[4 * i])).cwiseAbs().maxCoeff());
        alpha = std::max(alpha, std::fabs(double(back.opacities[i]) - c.opacities[i]));
        for (int j = 0; j < k; ++j)
            for (int ch = 0; ch < 3; ++ch) {
                const double e = std::fabs(double(back.sh[(i * k + j) * 3 + ch]) - c.sh[(i * k + j) * 3 + ch]);
                (j == 0 ? dc : j < 4 ? band1 : rest) = std::max(j == 0 ? dc : j < 4 ? band1 : rest, e);
            }
    }
    CHECK(pos <= 0.5 / 4096 + 1e-5);                // half a fixed-point step (+ float32 of |x| < 100)
    CHECK(logscale <= 0.5 / 16 + 1e-6);             // half a log-scale step
    CHECK(rot <= 4e-3);                             // 9-bit smallest three: ~1e-3 per component
    CHECK(alpha <= 0.5 / 255 + 1e-7);
    CHECK(dc <= 0.5 / 255 / spz::kColorScale + 1e-6);
    CHECK(band1 <= 4.5 / 128 + 1e-6);               // 5 bits: bucket of 8 in 1/128 steps
    CHECK(rest <= 8.5 / 128 + 1e-6);                // 4 bits: bucket of 16
}

}  // namespace

TEST_CASE("SPZ v4 and v3 round trips stay within the quantisation, SH degree 0..3", "[spz]") {
    for (int version : {4, 3})
        for (int degree = 0; degree <= 3; ++degree) {
            CAPTURE(version, degree);
            GaussianCloud c = random_cloud(500, degree, 7 + degree);
            c.antialiased = degree % 2 == 1;
            avsplat::SpzWriteOptions o;
            o.version = version;
            avsplat::write_spz(tmp("rt.spz"), c, o);
            const avsplat::SpzHeader h = avsplat::read_spz_header(tmp("rt.spz"));
            CHECK(h.version == version);
            CHECK(h.count == 500);
            CHECK(h.sh_degree == degree);
            CHECK(h.fractional_bits == 12);
            CHECK(h.antialiased == c.antialiased);
            const GaussianCloud back = avsplat::read_spz(tmp("rt.spz"));
            CHECK(back.antialiased == c.antialiased);
            check_within_quantisation(c, back);
            // A second round trip reproduces the bytes: decoding lands on the quantisation grid.
            avsplat::write_spz(tmp("rt2.spz"), back, o);
            CHECK(avsplat::read_spz(tmp("rt2.spz")).means == back.means);
            CHECK(avsplat::read_spz(tmp("rt2.spz")).sh == back.sh);
        }
}

TEST_CASE("SPZ stores a hand-computed Gaussian in RUB with the reference's codes", "[spz]") {
    GaussianCloud c(1, 1);
    c.means = {1.f, 2.f, -3.f};           // RDF; the file holds RUB (1, -2, 3)
    c.scales = {std::exp(-10.f), 1.f, std::exp(2.f)};
    c.rotations = {1, 0, 0, 0};
    c.opacities = {0.5f};
    c.sh = {0.f, 1.f, -1.f,               // DC
            0.5f, 0.f, 0.f,               // band 1, m = -1 (odd in y: negated in RUB)
            0.f, 0.25f, 0.f,              // m = 0 (z: negated)
            0.f, 0.f, 0.1f};              // m = 1 (x: kept)
    avsplat::write_spz(tmp("one.spz"), c);
    const std::vector<std::uint8_t> bytes = file_bytes(tmp("one.spz"));
    const spz::PackedSpz p = spz::unpack_container(bytes.data(), bytes.size(), "one.spz");
    REQUIRE(p.version == 4);
    CHECK(p.positions == std::vector<std::uint8_t>{0x00, 0x10, 0x00, 0x00, 0xe0, 0xff, 0x00, 0x30, 0x00});
    CHECK(p.alphas == std::vector<std::uint8_t>{128});  // round(127.5)
    CHECK(p.colors == std::vector<std::uint8_t>{128, 166, 89});  // round(255 (0.15 dc + 0.5))
    CHECK(p.scales == std::vector<std::uint8_t>{0, 160, 192});   // 16 (log s + 10)
    // Identity: largest is w (index 3), the others 0 with sign bits 0.
    CHECK(p.rotations == std::vector<std::uint8_t>{0, 0, 0, 0xc0});
    // round(128 c) + 128 to buckets of 8: -0.5 -> 64, -0.25 -> 96, 0.1 -> 141 -> 144, 0 -> 128.
    CHECK(p.sh == std::vector<std::uint8_t>{64, 128, 128, 128, 96, 128, 128, 128, 144});
}

TEST_CASE("SPZ axis changes rotate means, quaternions and SH as the brute-force evaluation does", "[spz]") {
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int a = 0; a < 8; ++a) {
        const auto axes = static_cast<SpzCoordinateSystem>(a);
        CAPTURE(a);
        const spz::AxisFlip f = spz::axis_flip(axes);
        const Eigen::Vector3d s(f.position[0], f.position[1], f.position[2]);
        std::vector<float> coeffs(48), flipped(48);
        for (auto& v : coeffs) v = float(u(rng));
        for (int j = 0; j < 16; ++j)
            for (int ch = 0; ch < 3; ++ch) flipped[j * 3 + ch] = (j == 0 ? 1.f : f.sh[j - 1]) * coeffs[j * 3 + ch];
        for (int trial = 0; trial < 20; ++trial) {
            const Eigen::Vector3d d = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
            const Eigen::Vector3d fd = s.cwiseProduct(d);
            double rgb[3], frgb[3];
            avsplat::sh::eval_sh(3, coeffs.data(), d.x(), d.y(), d.z(), rgb);
            avsplat::sh::eval_sh(3, flipped.data(), fd.x(), fd.y(), fd.z(), frgb);
            for (int ch = 0; ch < 3; ++ch) CHECK(frgb[ch] == Approx(rgb[ch]).margin(1e-6));
        }
        const Eigen::Quaterniond q = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized();
        const Eigen::Quaterniond fq(q.w(), f.quaternion_xyz[0] * q.x(), f.quaternion_xyz[1] * q.y(),
                                    f.quaternion_xyz[2] * q.z());
        const Eigen::Matrix3d F = s.asDiagonal();
        CHECK((fq.toRotationMatrix() - F * q.toRotationMatrix() * F).cwiseAbs().maxCoeff() < 1e-12);
    }
    // RUB <-> RDF is the 180-degree turn about x.
    const spz::AxisFlip rub = spz::axis_flip(SpzCoordinateSystem::RUB);
    CHECK(rub.position == std::array<float, 3>{1, -1, -1});
    const spz::AxisFlip rdf = spz::axis_flip(SpzCoordinateSystem::RDF);
    CHECK(rdf.position == std::array<float, 3>{1, 1, 1});
}

TEST_CASE("SPZ reading in other axes and writing in them agree", "[spz]") {
    const GaussianCloud c = random_cloud(50, 3, 11);
    avsplat::SpzWriteOptions o;
    o.coordinate_system = SpzCoordinateSystem::RDF;  // as splat-transform 3.7 stores PLY axes
    avsplat::write_spz(tmp("rdf.spz"), c, o);
    const GaussianCloud as_rdf = avsplat::read_spz(tmp("rdf.spz"), {SpzCoordinateSystem::RDF});
    check_within_quantisation(c, as_rdf);
    const GaussianCloud as_rub = avsplat::read_spz(tmp("rdf.spz"));
    for (std::size_t i = 0; i < c.size(); ++i) {
        CHECK(as_rub.means[3 * i] == as_rdf.means[3 * i]);
        CHECK(as_rub.means[3 * i + 1] == -as_rdf.means[3 * i + 1]);
        CHECK(as_rub.means[3 * i + 2] == -as_rdf.means[3 * i + 2]);
    }
}

TEST_CASE("SPZ positions take fewer fractional bits when the scene needs them", "[spz]") {
    GaussianCloud c(2, 0);
    c.means = {5000.f, 0.f, 0.f, -0.3f, 0.f, 0.f};
    avsplat::write_spz(tmp("big.spz"), c);
    CHECK(avsplat::read_spz_header(tmp("big.spz")).fractional_bits == 10);  // 5000 * 2^10 < 2^23
    const GaussianCloud back = avsplat::read_spz(tmp("big.spz"));
    CHECK(back.means[0] == 5000.f);
    CHECK(std::fabs(back.means[3] + 0.3f) <= 0.5 / 1024);
    c.means[0] = 1e7f;
    CHECK_THROWS_WITH(avsplat::write_spz(tmp("huge.spz"), c), Catch::Contains("GaussianCloud.means[0]"));
    avsplat::SpzWriteOptions o;
    o.fractional_bits = 12;
    c.means[0] = 3000.f;
    CHECK_THROWS_WITH(avsplat::write_spz(tmp("huge.spz"), c, o), Catch::Contains("24-bit"));
    c.means[0] = 1.f;
    o.version = 5;
    CHECK_THROWS_WITH(avsplat::write_spz(tmp("v5.spz"), c, o), Catch::Contains("version: 5 cannot be written (2, 3 and 4 can)"));
    o.version = 2;  // the older rotation encoding, for readers that predate 3
    avsplat::write_spz(tmp("v2.spz"), c, o);
    CHECK(avsplat::read_spz_header(tmp("v2.spz")).version == 2);
    CHECK(avsplat::read_spz(tmp("v2.spz")).means[0] == 1.f);
}

TEST_CASE("SPZ through read_gaussians and write_gaussians, recognised by content", "[spz]") {
    const GaussianCloud c = random_cloud(20, 2, 5);
    avsplat::write_gaussians(tmp("g.spz"), c);
    const std::vector<std::uint8_t> b = file_bytes(tmp("g.spz"));
    put_file(tmp("g_named.ply"), b);
    check_within_quantisation(c, avsplat::read_gaussians(tmp("g_named.ply")));
    avsplat::SpzWriteOptions o;
    o.version = 3;
    avsplat::write_spz(tmp("g3.spz"), c, o);
    put_file(tmp("g3.bin"), file_bytes(tmp("g3.spz")));
    CHECK(avsplat::is_spz_file(tmp("g3.bin")));
    check_within_quantisation(c, avsplat::read_gaussians(tmp("g3.bin")));
    CHECK_FALSE(avsplat::is_spz_file(tmp("missing.spz")));
}

TEST_CASE("SPZ: every truncation and bit flip gives IOError or a cloud, never a crash", "[spz]") {
    const GaussianCloud c = random_cloud(40, 3, 9);
    for (int version : {4, 3}) {
        avsplat::SpzWriteOptions o;
        o.version = version;
        avsplat::write_spz(tmp("h.spz"), c, o);
        const std::vector<std::uint8_t> good = file_bytes(tmp("h.spz"));
        for (std::size_t n = 0; n < good.size(); ++n) {
            CAPTURE(version, n);
            CHECK_THROWS_AS(avsplat::parse_spz(good.data(), n, "cut.spz"), avsplat::IOError);
        }
        std::mt19937 rng(version);
        for (int trial = 0; trial < 2000; ++trial) {
            std::vector<std::uint8_t> bad = good;
            bad[rng() % bad.size()] ^= std::uint8_t(1u << (rng() % 8));
            try {
                const GaussianCloud g = avsplat::parse_spz(bad.data(), bad.size(), "flip.spz");
                avsplat::validate(g);  // what is read is a valid cloud
            } catch (const avsplat::IOError& e) {
                CHECK(std::string(e.what()).rfind("flip.spz: ", 0) == 0);
            }
        }
    }
}

namespace {

// A v4 file from blocks whose sizes and header fields the test sets freely.
std::vector<std::uint8_t> v4_file(std::uint32_t count, int degree, const std::vector<std::vector<std::uint8_t>>& frames,
                                  const std::vector<std::uint64_t>& uncompressed) {
    std::vector<std::uint8_t> out = {'N', 'G', 'S', 'P', 4, 0, 0, 0};
    for (int k = 0; k < 4; ++k) out.push_back(std::uint8_t(count >> (8 * k)));
    out.insert(out.end(), {std::uint8_t(degree), 12, 0, std::uint8_t(frames.size()), 32, 0, 0, 0});
    out.resize(32, 0);
    for (std::size_t k = 0; k < frames.size(); ++k) {
        for (int b = 0; b < 8; ++b) out.push_back(std::uint8_t(std::uint64_t(frames[k].size()) >> (8 * b)));
        for (int b = 0; b < 8; ++b) out.push_back(std::uint8_t(uncompressed[k] >> (8 * b)));
    }
    for (const auto& f : frames) out.insert(out.end(), f.begin(), f.end());
    return out;
}

std::vector<std::uint8_t> zstd_frame(const std::vector<std::uint8_t>& data, bool with_size) {
    ZSTD_CCtx* cc = ZSTD_createCCtx();
    ZSTD_CCtx_setParameter(cc, ZSTD_c_contentSizeFlag, with_size ? 1 : 0);
    std::vector<std::uint8_t> out(ZSTD_compressBound(data.size()));
    ZSTD_outBuffer ob{out.data(), out.size(), 0};
    ZSTD_inBuffer ib{data.data(), data.size(), 0};
    while (ZSTD_compressStream2(cc, &ob, &ib, ZSTD_e_end) != 0) {}
    ZSTD_freeCCtx(cc);
    out.resize(ob.pos);
    return out;
}

}  // namespace

TEST_CASE("SPZ v4: lying sizes and decompression bombs give IOError before any large allocation", "[spz]") {
    const std::uint32_t n = 2;
    auto blocks = [&](std::uint32_t count) {
        return std::vector<std::uint64_t>{9ull * count, count, 3ull * count, 3ull * count, 4ull * count};
    };
    std::vector<std::vector<std::uint8_t>> frames;
    for (std::uint64_t s : blocks(n)) frames.push_back(zstd_frame(std::vector<std::uint8_t>(s, 0), true));
    frames[4] = zstd_frame(std::vector<std::uint8_t>{0, 0, 0, 0xc0, 0, 0, 0, 0xc0}, true);
    const std::vector<std::uint8_t> ok = v4_file(n, 0, frames, blocks(n));
    CHECK(avsplat::parse_spz(ok.data(), ok.size(), "ok.spz").size() == 2);

    // A header claiming 4 billion Gaussians whose table agrees: 86 GB in a file of ~150 bytes
    // is refused by the frames' declared sizes before anything is decompressed.
    const std::uint32_t lots = 0xffffffffu;
    const auto lying = v4_file(lots, 0, frames, blocks(lots));
    CHECK_THROWS_WITH(avsplat::parse_spz(lying.data(), lying.size(), "bomb.spz"),
                      Catch::Contains("bomb.spz: toc[0] (positions): ZSTD frame holds 18 bytes, the header implies "
                                      "38654705655"));
    // 40000 Gaussians, 800 KB: a frame that declares its size is refused by it, one that does not
    // is decoded only as far as it goes.
    const std::uint32_t some = 40000;
    const auto sized = v4_file(some, 0, frames, blocks(some));
    CHECK_THROWS_WITH(avsplat::parse_spz(sized.data(), sized.size(), "bomb.spz"),
                      Catch::Contains("bomb.spz: toc[0] (positions): ZSTD frame holds 18 bytes, the header implies "
                                      "360000"));
    std::vector<std::vector<std::uint8_t>> unsized;
    for (std::uint64_t s : blocks(n)) unsized.push_back(zstd_frame(std::vector<std::uint8_t>(s, 0), false));
    const auto claim = v4_file(some, 0, unsized, blocks(some));
    CHECK_THROWS_WITH(avsplat::parse_spz(claim.data(), claim.size(), "bomb.spz"),
                      Catch::Contains("positions: ZSTD stream holds 18 bytes, the header implies 360000"));
    // A real bomb: 256 MiB of zeros in a small frame without a declared size, where the header
    // implies 18 bytes: decoding stops one byte past them.
    {
        ZSTD_CCtx* cc = ZSTD_createCCtx();
        ZSTD_CCtx_setParameter(cc, ZSTD_c_contentSizeFlag, 0);
        std::vector<std::uint8_t> zeros(1 << 20, 0), out(1 << 22);
        ZSTD_outBuffer ob{out.data(), out.size(), 0};
        for (int k = 0; k < 256; ++k) {
            ZSTD_inBuffer ib{zeros.data(), zeros.size(), 0};
            ZSTD_compressStream2(cc, &ob, &ib, ZSTD_e_continue);
        }
        ZSTD_inBuffer ib{nullptr, 0, 0};
        while (ZSTD_compressStream2(cc, &ob, &ib, ZSTD_e_end) != 0) {}
        ZSTD_freeCCtx(cc);
        out.resize(ob.pos);
        REQUIRE(out.size() < (1 << 20));
        std::vector<std::vector<std::uint8_t>> bomb = unsized;
        bomb[0] = out;
        const auto file = v4_file(n, 0, bomb, blocks(n));
        CHECK_THROWS_WITH(avsplat::parse_spz(file.data(), file.size(), "bomb.spz"),
                          Catch::Contains("positions: ZSTD stream holds more than the 18 bytes"));
    }
    // The table disagrees with the header.
    auto lie = blocks(n);
    lie[2] += 3;
    CHECK_THROWS_WITH(avsplat::parse_spz(v4_file(n, 0, frames, lie).data(), v4_file(n, 0, frames, lie).size(), "lie.spz"),
                      Catch::Contains("toc[2] (colors): uncompressedSize 9, the header implies 6"));
    // Too few streams for the SH degree; a compressed size past the end of the file.
    CHECK_THROWS_WITH(avsplat::parse_spz(v4_file(n, 1, frames, blocks(n)).data(), v4_file(n, 1, frames, blocks(n)).size(), "x.spz"),
                      Catch::Contains("numStreams: 5, expected 6"));
    std::vector<std::uint8_t> past = ok;
    past[32] = 0xff, past[33] = 0xff;
    CHECK_THROWS_WITH(avsplat::parse_spz(past.data(), past.size(), "x.spz"),
                      Catch::Contains("toc[0] (positions): compressedSize 65535 runs past the end"));
    std::vector<std::uint8_t> version = ok;
    version[4] = 9;
    CHECK_THROWS_WITH(avsplat::parse_spz(version.data(), version.size(), "x.spz"), Catch::Contains("version: 9"));
    std::vector<std::uint8_t> degree = ok;
    degree[12] = 5;
    CHECK_THROWS_WITH(avsplat::parse_spz(degree.data(), degree.size(), "x.spz"), Catch::Contains("shDegree: 5"));
}

TEST_CASE("SPZ v3: a lying count and a file that is not SPZ give IOError naming the file", "[spz]") {
    const GaussianCloud c = random_cloud(10, 1, 2);
    avsplat::SpzWriteOptions o;
    o.version = 3;
    avsplat::write_spz(tmp("v3.spz"), c, o);
    // Rewrite the count inside the gzip stream: fewer and more Gaussians than the stream holds.
    const std::vector<std::uint8_t> good = file_bytes(tmp("v3.spz"));
    const spz::PackedSpz p = spz::unpack_container(good.data(), good.size(), "v3.spz");
    for (std::uint32_t count : {9u, 11u, 0xffffffffu}) {
        spz::PackedSpz q = p;
        q.count = count;
        q.version = 3;
        const std::vector<std::uint8_t> bad = spz::pack_container(q);
        CAPTURE(count);
        CHECK_THROWS_WITH(avsplat::parse_spz(bad.data(), bad.size(), "count.spz"), Catch::Contains("count.spz: numPoints"));
    }
    put_file(tmp("text.spz"), {'h', 'e', 'l', 'l', 'o'});
    CHECK_THROWS_WITH(avsplat::read_spz(tmp("text.spz")), Catch::Contains("text.spz: magic"));
    CHECK_THROWS_AS(avsplat::read_spz(tmp("absent.spz")), avsplat::IOError);
}

TEST_CASE("SPZ v4 of identical Gaussians, far smaller than deflate could make it, reads back", "[spz]") {
    avsplat::GaussianCloud c(100000, 0);
    for (auto& s : c.scales) s = 0.01f;
    const std::string path = std::string(AVSPLAT_TEST_TMP) + "/identical.spz";
    avsplat::write_spz(path, c);
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    CHECK(in.tellg() < 2000);
    CHECK(avsplat::read_spz(path).size() == 100000);
}
