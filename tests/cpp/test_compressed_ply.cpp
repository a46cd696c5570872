// PlayCanvas compressed PLY (io/compressed_ply.h): hand-computed bytes, round trips within the
// format's quantisation (bounds derived here from the cloud, independently of the writer),
// detection by content, and corrupt files.
#include "avsplat/core/error.h"
#include "avsplat/core/sh.h"
#include "avsplat/io/compressed_ply.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/ply.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <numeric>
#include <random>
#include <string>
#include <vector>

using avsplat::GaussianCloud;

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
}

void dump(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary);
    out << bytes;
}

GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f), pos(0.f, 1.f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = 3.f * u(rng);
    for (auto& v : c.scales) v = std::exp(-5.f + 3.f * pos(rng));
    for (auto& v : c.rotations) v = u(rng);
    for (auto& v : c.opacities) v = pos(rng);
    for (auto& v : c.sh) v = 1.5f * u(rng);
    return c;
}

std::uint32_t word(const std::string& bytes, std::size_t offset) {
    std::uint32_t v = 0;
    for (int k = 0; k < 4; ++k) v |= std::uint32_t(static_cast<unsigned char>(bytes[offset + k])) << (8 * k);
    return v;
}

}  // namespace

TEST_CASE("compressed PLY packs two Gaussians as computed by hand", "[compressed_ply]") {
    GaussianCloud c(2, 0);
    c.means = {0, 0, 0, 1, 2, 3};
    c.scales = {1, 1, 1, 1, 1, 1};
    c.rotations = {1, 0, 0, 0, 0, 0, 0, -2};  // identity; a 180 degree turn about z (largest z < 0)
    c.opacities = {0.5f, 1.f};
    avsplat::write_compressed_ply(tmp("hand.compressed.ply"), c, false);
    const std::string b = slurp(tmp("hand.compressed.ply"));
    const std::size_t data = b.find("end_header\n") + 11;
    REQUIRE(b.size() == data + 18 * 4 + 2 * 16);
    float bounds[18];
    std::memcpy(bounds, b.data() + data, sizeof bounds);
    CHECK(bounds[0] == 0.f);  // min_x
    CHECK(bounds[4] == 2.f);  // max_y
    CHECK(bounds[6] == 0.f);  // min_scale_x = log 1
    const std::size_t v = data + 72;
    CHECK(word(b, v) == 0u);                                      // position at the minimum
    CHECK(word(b, v + 16) == (2047u << 21 | 1023u << 11 | 2047u));  // at the maximum
    // Identity: largest index 0, others 0 -> round(0.5 * 1023) = 512.
    CHECK(word(b, v + 4) == (0u << 30 | 512u << 20 | 512u << 10 | 512u));
    // (0, 0, 0, -1) made positive: largest index 3.
    CHECK(word(b, v + 16 + 4) == (3u << 30 | 512u << 20 | 512u << 10 | 512u));
    CHECK((word(b, v + 12) & 0xff) == 128u);       // opacity 0.5 -> floor(127.5 + 0.5)
    CHECK((word(b, v + 16 + 12) & 0xff) == 255u);  // opacity 1
    // Scales equal across the chunk (max - min < 1e-5) pack as 0 and decode to the minimum.
    CHECK(word(b, v + 8) == 0u);

    const GaussianCloud back = avsplat::read_compressed_ply(tmp("hand.compressed.ply"));
    REQUIRE(back.size() == 2);
    CHECK(back.sh_degree == 0);
    CHECK(back.means == c.means);
    CHECK(back.scales == c.scales);
    CHECK(back.opacities[1] == 1.f);
    CHECK(back.opacities[0] == Approx(128.0 / 255.0));
    CHECK(back.rotations[4 + 3] == Approx(1.0).margin(1e-3));  // the sign of the whole quaternion is free
}

TEST_CASE("compressed PLY round trip stays within the format's quantisation", "[compressed_ply]") {
    for (int degree = 0; degree <= 3; ++degree) {
        const GaussianCloud c = random_cloud(700, degree, 10 + degree);  // three chunks, the last partial
        const std::string path = tmp("rt" + std::to_string(degree) + ".compressed.ply");
        avsplat::write_compressed_ply(path, c, false);
        const GaussianCloud back = avsplat::read_compressed_ply(path);
        REQUIRE(back.size() == c.size());
        REQUIRE(back.sh_degree == degree);
        const int K = c.sh_coeffs();
        for (std::size_t first = 0; first < c.size(); first += 256) {
            const std::size_t last = std::min(c.size(), first + 256);
            for (int a = 0; a < 3; ++a) {
                double lo = 1e30, hi = -1e30, slo = 1e30, shi = -1e30, clo = 1e30, chi = -1e30;
                for (std::size_t i = first; i < last; ++i) {
                    lo = std::min(lo, double(c.means[3 * i + a]));
                    hi = std::max(hi, double(c.means[3 * i + a]));
                    slo = std::min(slo, std::log(double(c.scales[3 * i + a])));
                    shi = std::max(shi, std::log(double(c.scales[3 * i + a])));
                    clo = std::min(clo, avsplat::sh::dc_to_color<double>(c.sh[i * 3 * K + a]));
                    chi = std::max(chi, avsplat::sh::dc_to_color<double>(c.sh[i * 3 * K + a]));
                }
                const double steps = a == 1 ? 1023 : 2047;
                for (std::size_t i = first; i < last; ++i) {
                    INFO("degree " << degree << " Gaussian " << i << " axis " << a);
                    CHECK(std::fabs(back.means[3 * i + a] - c.means[3 * i + a]) <= (hi - lo) / (2 * steps) + 1e-6);
                    CHECK(std::fabs(std::log(back.scales[3 * i + a]) - std::log(c.scales[3 * i + a])) <= (shi - slo) / (2 * steps) + 1e-5);
                    const double colour = avsplat::sh::dc_to_color<double>(back.sh[i * 3 * K + a]);
                    CHECK(std::fabs(colour - avsplat::sh::dc_to_color<double>(c.sh[i * 3 * K + a])) <= (chi - clo) / 510 + 1e-6);
                }
            }
        }
        double worst_rot = 0, worst_sh = 0, worst_opacity = 0;
        for (std::size_t i = 0; i < c.size(); ++i) {
            double n = 0, dot = 0;
            for (int k = 0; k < 4; ++k) n += double(c.rotations[4 * i + k]) * c.rotations[4 * i + k];
            for (int k = 0; k < 4; ++k) dot += back.rotations[4 * i + k] * c.rotations[4 * i + k] / std::sqrt(n);
            worst_rot = std::max(worst_rot, 1 - std::fabs(dot));
            worst_opacity = std::max(worst_opacity, double(std::fabs(back.opacities[i] - c.opacities[i])));
            for (int k = 3; k < 3 * K; ++k)
                worst_sh = std::max(worst_sh, double(std::fabs(back.sh[i * 3 * K + k] - c.sh[i * 3 * K + k])));
        }
        CHECK(worst_opacity <= 0.5 / 255 + 1e-6);
        CHECK(worst_sh <= 8.0 / 256 + 1e-6);  // half a step, or a whole one at the clamped ends
        CHECK(worst_rot < 4e-6);               // 1 - |cos(angle / 2)|: angle below about 0.33 degrees
        CHECK(worst_rot > 0);                  // the format is lossy: a check that could not fail is no check
    }
}

TEST_CASE("compressed PLY is found by content and by name", "[compressed_ply][gaussian_io]") {
    const GaussianCloud c = random_cloud(300, 2, 3);
    avsplat::write_gaussians(tmp("byname.COMPRESSED.PLY"), c);
    const GaussianCloud ref = avsplat::read_compressed_ply(tmp("byname.COMPRESSED.PLY"));
    CHECK(avsplat::detect_gaussian_format(tmp("byname.COMPRESSED.PLY")).format == avsplat::GaussianFormat::CompressedPly);
    CHECK(avsplat::detect_gaussian_format(tmp("byname.COMPRESSED.PLY")).version == "2 (chunk colour bounds)");
    // Renamed to a plain .ply or to anything: read_ply and read_gaussians still decode it.
    const std::string bytes = slurp(tmp("byname.COMPRESSED.PLY"));
    dump(tmp("renamed.ply"), bytes);
    dump(tmp("renamed.data"), bytes);
    CHECK(avsplat::read_ply(tmp("renamed.ply")).means == ref.means);
    CHECK(avsplat::read_gaussians(tmp("renamed.data")).sh == ref.sh);
    const GaussianCloud mem = avsplat::parse_compressed_ply(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), "mem");
    CHECK(mem.rotations == ref.rotations);
    // Morton order by default: the file holds the Gaussians in morton_order().
    const std::vector<std::size_t> order = avsplat::morton_order(c);
    std::vector<std::size_t> sorted = order;
    std::sort(sorted.begin(), sorted.end());
    for (std::size_t i = 0; i < sorted.size(); ++i) REQUIRE(sorted[i] == i);
    avsplat::write_compressed_ply(tmp("kept.compressed.ply"), avsplat::select(c, order), false);
    CHECK(slurp(tmp("kept.compressed.ply")) == bytes);

    avsplat::write_ply(tmp("plain.ply"), c);
    CHECK(avsplat::detect_gaussian_format(tmp("plain.ply")).format == avsplat::GaussianFormat::Ply);
    CHECK(avsplat::detect_gaussian_format(tmp("plain.ply")).version == "binary_little_endian 1.0");
    CHECK(avsplat::gaussian_format_for_name("a/b.compressed.ply") == avsplat::GaussianFormat::CompressedPly);
    CHECK(avsplat::gaussian_format_for_name("a.compressed/b.ply") == avsplat::GaussianFormat::Ply);
    CHECK(avsplat::gaussian_format_for_name("b.Splat") == avsplat::GaussianFormat::Splat);
    // Every format of the table is written by its name and found again by its content.
    const std::pair<const char*, avsplat::GaussianFormat> names[] = {
        {"x.spz", avsplat::GaussianFormat::Spz}, {"x.sog", avsplat::GaussianFormat::Sog},
        {"x.splat", avsplat::GaussianFormat::Splat}, {"x.compressed.ply", avsplat::GaussianFormat::CompressedPly}};
    for (const auto& [name, format] : names) {
        avsplat::write_gaussians(tmp(name), c);
        CHECK(avsplat::detect_gaussian_format(tmp(name)).format == format);
        CHECK(avsplat::read_gaussians(tmp(name)).size() == c.size());
    }
    CHECK(avsplat::detect_gaussian_format(tmp("x.spz")).version == "4");
    CHECK_THROWS_WITH(avsplat::write_gaussians(tmp("x.xyz"), c), Catch::Contains("unsupported extension"));
}

TEST_CASE("Morton order keeps chunks compact", "[compressed_ply]") {
    // A 16^3 grid, shuffled: in input order every chunk of 256 spans nearly the whole grid
    // (volume 16^3); in Morton order each spans a small block, so its bounds are tight.
    GaussianCloud c(4096, 0);
    std::vector<std::size_t> perm(4096);
    std::iota(perm.begin(), perm.end(), std::size_t(0));
    std::shuffle(perm.begin(), perm.end(), std::mt19937(5));
    for (std::size_t i = 0; i < 4096; ++i) {
        const std::size_t g = perm[i];
        c.means[3 * i] = float(g % 16);
        c.means[3 * i + 1] = float(g / 16 % 16);
        c.means[3 * i + 2] = float(g / 256);
    }
    const auto order = avsplat::morton_order(c);
    for (std::size_t first = 0; first < 4096; first += 256) {
        float volume = 1;
        for (int a = 0; a < 3; ++a) {
            float lo = 1e9f, hi = -1e9f;
            for (std::size_t j = first; j < first + 256; ++j) {
                lo = std::min(lo, c.means[3 * order[j] + a]);
                hi = std::max(hi, c.means[3 * order[j] + a]);
            }
            volume *= hi - lo + 1;
        }
        CHECK(volume <= 512.f);
    }
}

namespace {

// The Morton order as documented (splat-transform's sortMortonStrided), written plainly: the bits
// of the three 10-bit cells interleaved one at a time, a stable sort by code, and buckets of more
// than 256 equal codes sorted again over their own bounds.
void morton_reference(std::vector<std::size_t>& idx, std::size_t first, std::size_t count, const std::vector<float>& means) {
    if (count == 0) return;
    double lo[3], hi[3], mul[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = 1e300;
        hi[a] = -1e300;
        for (std::size_t k = first; k < first + count; ++k) {
            lo[a] = std::min(lo[a], double(means[3 * idx[k] + a]));
            hi[a] = std::max(hi[a], double(means[3 * idx[k] + a]));
        }
    }
    if (hi[0] == lo[0] && hi[1] == lo[1] && hi[2] == lo[2]) return;
    for (int a = 0; a < 3; ++a) mul[a] = hi[a] == lo[a] ? 0.0 : 1024 / (hi[a] - lo[a]);
    auto code = [&](std::size_t i) {
        std::uint32_t out = 0;
        for (int a = 0; a < 3; ++a) {
            const auto cell = std::uint32_t(std::min(1023.0, (double(means[3 * i + a]) - lo[a]) * mul[a]));
            for (int bit = 0; bit < 10; ++bit) out |= ((cell >> bit) & 1u) << (3 * bit + a);
        }
        return out;
    };
    std::stable_sort(idx.begin() + std::ptrdiff_t(first), idx.begin() + std::ptrdiff_t(first + count),
                     [&](std::size_t i, std::size_t j) { return code(i) < code(j); });
    for (std::size_t s = first; s < first + count;) {
        std::size_t e = s + 1;
        while (e < first + count && code(idx[e]) == code(idx[s])) ++e;
        if (e - s > 256) morton_reference(idx, s, e - s, means);
        s = e;
    }
}

}  // namespace

TEST_CASE("Morton order: as the plain stable sort by code, over a subset and order of rows too", "[compressed_ply]") {
    // A spread cloud with a dense knot of 3000 points (one code at the top level: sorted again
    // inside), exact duplicates and shared cells (ties keep the order given).
    std::mt19937 rng(21);
    std::uniform_real_distribution<float> u(-10.f, 10.f), knot(0.f, 1e-3f);
    GaussianCloud c(6000, 0);
    for (std::size_t i = 0; i < c.size(); ++i)
        for (int a = 0; a < 3; ++a) c.means[3 * i + a] = i < 3000 ? u(rng) : 2.f + knot(rng);
    for (std::size_t i = 0; i < 200; ++i)
        for (int a = 0; a < 3; ++a) c.means[3 * (2 * i + 1) + a] = c.means[3 * (2 * i) + a];
    std::vector<std::size_t> all(c.size());
    std::iota(all.begin(), all.end(), std::size_t(0));
    std::vector<std::size_t> ref = all;
    morton_reference(ref, 0, ref.size(), c.means);
    CHECK(avsplat::morton_order(c) == ref);
    // Rows given in a shuffled order, and a subset: ties in the order given.
    std::vector<std::size_t> rows = all;
    std::shuffle(rows.begin(), rows.end(), std::mt19937(3));
    for (std::size_t keep : {c.size(), std::size_t(4500)}) {
        const std::vector<std::size_t> some(rows.begin(), rows.begin() + std::ptrdiff_t(keep));
        std::vector<std::size_t> expect = some;
        morton_reference(expect, 0, expect.size(), c.means);
        CHECK(avsplat::morton_order(c, some) == expect);
        // The same as the order of the copied rows, mapped back.
        const std::vector<std::size_t> copied = avsplat::morton_order(avsplat::select(c, some));
        std::vector<std::size_t> mapped(copied.size());
        for (std::size_t k = 0; k < copied.size(); ++k) mapped[k] = some[copied[k]];
        CHECK(mapped == expect);
    }
    CHECK_THROWS_WITH(avsplat::morton_order(c, {0, 6000}), Catch::Contains("rows[1] = 6000"));
}

TEST_CASE("corrupt compressed PLY files give an IOError naming the file", "[compressed_ply][corrupt]") {
    const GaussianCloud c = random_cloud(300, 1, 7);
    avsplat::write_compressed_ply(tmp("good.compressed.ply"), c);
    const std::string good = slurp(tmp("good.compressed.ply"));
    auto expect = [&](const std::string& bytes, const std::string& what) {
        const std::string path = tmp("bad.compressed.ply");
        dump(path, bytes);
        INFO(what);
        CHECK_THROWS_AS(avsplat::read_compressed_ply(path), avsplat::IOError);
        CHECK_THROWS_WITH(avsplat::read_compressed_ply(path), Catch::Contains(path) && Catch::Contains(what));
        CHECK_THROWS_WITH(avsplat::read_gaussians(path), Catch::Contains(path));
        CHECK_THROWS_AS(avsplat::parse_compressed_ply(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), "mem"),
                        avsplat::IOError);
    };
    auto replace = [&](std::string s, const std::string& from, const std::string& to) {
        const auto at = s.find(from);
        REQUIRE(at != std::string::npos);
        return s.replace(at, from.size(), to);
    };
    for (std::size_t cut : {good.size() - 1, good.size() - 300, good.size() / 2, std::size_t(40)})
        expect(good.substr(0, cut), cut < 100 ? "" : "truncated");
    expect(good + "x", "bytes after the last element");
    expect(replace(good, "element chunk 2", "element chunk 1"), "chunk element has 1 rows; 300 vertices need");
    expect(replace(good, "element chunk 2", "element chunk 9"), "chunk element has 9 rows");
    expect(replace(good, "element chunk 2", "element chunk 99999999999"), "chunk element has 99999999999 rows");
    expect(replace(good, "element vertex 300", "element vertex 301"), "");
    expect(replace(good, "element sh 300", "element sh 299"), "sh element has 299 rows for 300 vertices");
    expect(replace(good, "packed_scale", "packed_scalf"), "vertex element has no \"packed_scale\" property");
    expect(replace(good, "property float max_scale_y", "property float max_scale_q"), "no \"max_scale_y\"");
    expect(replace(good, "property float min_g", "property float min_q"), "of the 6 colour bounds");
    expect(replace(good, "element chunk", "element chunks"), "no \"chunk\" element");
    expect(replace(good, "uint packed_color", "int packed_color"), "is int; compressed PLY packs it in a uint32");
    expect(replace(good, "uchar f_rest_8", "uchar f_rest_9"), "no \"f_rest_8\"");
    expect(replace(good, "binary_little_endian", "ascii"), "ASCII");
    // A NaN bound: the first chunk's min_x.
    std::string nan_bound = good;
    const std::size_t data = good.find("end_header\n") + 11;
    const float nan = std::nanf("");
    std::memcpy(&nan_bound[data], &nan, 4);
    expect(nan_bound, "chunk row 0: \"min_x\" = nan is not finite or decodes outside the float32 range");
    // A log-scale bound whose exp overflows float32 (a float in the file, but e^100 is not one).
    std::string huge_scale = good;
    const float hundred = 100.f;
    std::memcpy(&huge_scale[data + 4 * 10], &hundred, 4);  // max_scale_y of chunk 0
    expect(huge_scale, "chunk row 0: \"max_scale_y\" = 100.000000 (a log scale) is not finite");
}

TEST_CASE("compressed PLY of the first version (no colour bounds) reads colours as plain unorm", "[compressed_ply]") {
    const GaussianCloud c = random_cloud(300, 0, 9);
    avsplat::write_compressed_ply(tmp("v2.compressed.ply"), c, false);
    const std::string v2 = slurp(tmp("v2.compressed.ply"));
    // Drop the six colour bounds from the header and from every chunk row (the last 24 of 72 bytes).
    std::string header = v2.substr(0, v2.find("end_header\n") + 11);
    for (const char* name : {"min_r", "min_g", "min_b", "max_r", "max_g", "max_b"}) {
        const std::string line = std::string("property float ") + name + "\n";
        header.erase(header.find(line), line.size());
    }
    std::string body = v2.substr(v2.find("end_header\n") + 11);
    for (int chunk = 1; chunk >= 0; --chunk) body.erase(static_cast<std::size_t>(chunk) * 72 + 48, 24);
    dump(tmp("v1.compressed.ply"), header + body);
    CHECK(avsplat::detect_gaussian_format(tmp("v1.compressed.ply")).version == "1 (no chunk colour bounds)");
    const GaussianCloud v1 = avsplat::read_compressed_ply(tmp("v1.compressed.ply"));
    const GaussianCloud ref = avsplat::read_compressed_ply(tmp("v2.compressed.ply"));
    CHECK(v1.means == ref.means);
    CHECK(v1.rotations == ref.rotations);
    for (std::size_t i = 0; i < c.size(); ++i) {
        const std::uint32_t colour = word(body, 2 * 48 + 16 * i + 12);
        for (int ch = 0; ch < 3; ++ch) {
            const double t = double((colour >> (24 - 8 * ch)) & 255u) / 255.0;
            CHECK(v1.sh[3 * i + ch] == static_cast<float>(avsplat::sh::color_to_dc(t)));
        }
    }
}
