// Tests of the 3DGS PLY reader and writer.
//
// Reference data is built here independently of lib/src/io/ply.cpp: files are assembled byte by
// byte (either endianness) or as text, expected values are computed by hand or in double
// precision, and the writer's output is parsed by a small decoder written in this file.
#include "avsplat/io/ply.h"

#include "avsplat/core/error.h"

#include <catch2/catch.hpp>

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using avsplat::GaussianCloud;
using avsplat::IOError;
using avsplat::read_ply;
using avsplat::write_ply;
using Catch::Matchers::Contains;

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/ply_" + name; }

void write_file(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    REQUIRE(out.good());
}

std::string read_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream os;
    os << in.rdbuf();
    return os.str();
}

std::uint32_t bits(float v) {
    std::uint32_t b;
    std::memcpy(&b, &v, 4);
    return b;
}

// Index of the first element whose bits differ, or -1 when the arrays are bit-identical.
long first_bit_mismatch(const std::vector<float>& a, const std::vector<float>& b) {
    if (a.size() != b.size()) return static_cast<long>(std::min(a.size(), b.size()));
    for (std::size_t i = 0; i < a.size(); ++i)
        if (bits(a[i]) != bits(b[i])) return static_cast<long>(i);
    return -1;
}

// Distance in units in the last place between two non-negative floats.
long ulp_distance(float a, float b) { return std::labs(static_cast<long>(bits(a)) - static_cast<long>(bits(b))); }

// Bytes of a PLY body in either byte order, emitted most significant byte first for big endian
// by shifting the bit pattern (not by reversing a memcpy, as the reader does).
struct Body {
    bool big = false;
    std::string bytes;

    template <class T>
    void put(T v) {
        static_assert(std::is_arithmetic<T>::value, "scalar");
        std::uint64_t u = 0;
        if constexpr (std::is_floating_point<T>::value) {
            if constexpr (sizeof(T) == 4) {
                std::uint32_t b;
                std::memcpy(&b, &v, 4);
                u = b;
            } else {
                std::memcpy(&u, &v, 8);
            }
        } else {
            u = static_cast<std::uint64_t>(static_cast<std::make_unsigned_t<T>>(v));
        }
        for (std::size_t k = 0; k < sizeof(T); ++k) {
            const std::size_t shift = big ? 8 * (sizeof(T) - 1 - k) : 8 * k;
            bytes.push_back(static_cast<char>((u >> shift) & 0xff));
        }
    }
};

double sigmoid(double l) { return 1.0 / (1.0 + std::exp(-l)); }

// A cloud with every field exercised: scales log-uniform over [1e-6, 1e3], opacities uniform in
// (0, 1), rotations not normalised.
GaussianCloud random_cloud(std::size_t n, int degree, bool confidence, int extras, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    std::uniform_real_distribution<double> log_scale(std::log(1e-6), std::log(1e3));
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = 10.0f * normal(rng);
    for (auto& v : c.scales) v = static_cast<float>(std::exp(log_scale(rng)));
    for (auto& v : c.rotations) v = normal(rng);
    for (auto& v : c.opacities) {
        do v = unit(rng); while (v <= 0.0f);
    }
    for (auto& v : c.sh) v = normal(rng);
    if (confidence) {
        c.confidence.resize(n);
        for (auto& v : c.confidence) v = normal(rng);
    }
    for (int e = 0; e < extras; ++e) {
        std::vector<float> values(n);
        for (auto& v : values) v = 100.0f * normal(rng);
        c.set_extra("extra_" + std::to_string(e), std::move(values));
    }
    return c;
}

// Largest error, in ulp of v, that float32 storage of its encoding L can force on the decoded
// value: half the gap between the decodes of neighbouring floats (dv/dL times ulp(L)), plus
// one ulp for rounding the decoded value.
double allowed_ulps(double v, double L, double dv_dL) {
    const float Lf = static_cast<float>(std::fabs(L));
    const double ulp_L = static_cast<double>(std::nextafter(Lf, std::numeric_limits<float>::infinity())) - Lf;
    const float vf = static_cast<float>(v);
    const double ulp_v = static_cast<double>(std::nextafter(vf, std::numeric_limits<float>::infinity())) - vf;
    return std::floor(0.5 * dv_dL * ulp_L / ulp_v) + 1.0;
}

void require_same_shapes(const GaussianCloud& a, const GaussianCloud& b) {
    REQUIRE(a.size() == b.size());
    REQUIRE(a.sh_degree == b.sh_degree);
    REQUIRE(a.means.size() == b.means.size());
    REQUIRE(a.sh.size() == b.sh.size());
    REQUIRE(a.has_confidence() == b.has_confidence());
    REQUIRE(a.extras.size() == b.extras.size());
    for (std::size_t k = 0; k < a.extras.size(); ++k) REQUIRE(a.extras[k].name == b.extras[k].name);
}

// What a reader's result must be: a cloud whose arrays have consistent sizes.
bool consistent_shapes(const GaussianCloud& c) {
    const std::size_t n = c.size();
    if (c.sh_degree < 0 || c.sh_degree > 3) return false;
    if (c.means.size() != 3 * n || c.scales.size() != 3 * n || c.rotations.size() != 4 * n) return false;
    if (c.sh.size() != n * static_cast<std::size_t>(c.sh_coeffs()) * 3) return false;
    if (!c.confidence.empty() && c.confidence.size() != n) return false;
    for (const auto& e : c.extras)
        if (e.values.size() != n) return false;
    return true;
}

// Reads `path`; a failure must be an IOError that names the file. Returns whether it read.
bool read_succeeds_or_io_error(const std::string& path) {
    try {
        const GaussianCloud c = read_ply(path);
        REQUIRE(consistent_shapes(c));
        return true;
    } catch (const IOError& e) {
        REQUIRE_THAT(e.what(), Contains(path));
        return false;
    } catch (const std::exception& e) {
        FAIL("read_ply threw a non-IOError exception: " << e.what());
    } catch (...) {
        FAIL("read_ply threw a non-standard exception");
    }
    return false;
}

}  // namespace

TEST_CASE("write_ply then read_ply: SH degrees 0..3 with confidence and extras", "[ply]") {
    for (int degree = 0; degree <= 3; ++degree) {
        for (bool with_conf : {false, true}) {
            DYNAMIC_SECTION("degree " << degree << (with_conf ? " with" : " without") << " confidence") {
                const GaussianCloud c = random_cloud(300, degree, with_conf, with_conf ? 2 : 0, 10 + degree);
                const std::string path = tmp("roundtrip_" + std::to_string(degree) + ".ply");
                write_ply(path, c);
                const GaussianCloud r = read_ply(path);
                require_same_shapes(c, r);
                CHECK(first_bit_mismatch(c.means, r.means) == -1);
                CHECK(first_bit_mismatch(c.rotations, r.rotations) == -1);
                CHECK(first_bit_mismatch(c.sh, r.sh) == -1);
                CHECK(first_bit_mismatch(c.confidence, r.confidence) == -1);
                for (std::size_t k = 0; k < c.extras.size(); ++k)
                    CHECK(first_bit_mismatch(c.extras[k].values, r.extras[k].values) == -1);
                // Log / logit storage: bounded, see the precision test below.
                for (std::size_t i = 0; i < c.size(); ++i) {
                    CHECK(ulp_distance(c.opacities[i], r.opacities[i]) <= 8);
                    for (int a = 0; a < 3; ++a) CHECK(ulp_distance(c.scales[3 * i + a], r.scales[3 * i + a]) <= 8);
                }
            }
        }
    }
}

TEST_CASE("read_ply: a file read by pieces on every thread equals one read on one thread", "[ply]") {
    // 40,000 degree-3 Gaussians (9.9 MB): many pieces, read in parallel; bit-identical to the
    // values written and to a one-thread read, and a file cut short is still an error.
    const GaussianCloud ref = random_cloud(40000, 3, true, 1, 77);
    const std::string path = tmp("pieces.ply");
    write_ply(path, ref);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const GaussianCloud one = read_ply(path);
    omp_set_num_threads(std::max(2, threads));
    const GaussianCloud many = read_ply(path);
    omp_set_num_threads(threads);
    for (const GaussianCloud* c : {&one, &many}) {
        CHECK(c->means == ref.means);
        CHECK(c->rotations == ref.rotations);
        CHECK(c->sh == ref.sh);
        CHECK(c->confidence == ref.confidence);
    }
    CHECK(std::memcmp(one.scales.data(), many.scales.data(), 4 * one.scales.size()) == 0);
    CHECK(std::memcmp(one.opacities.data(), many.opacities.data(), 4 * one.opacities.size()) == 0);
    std::ifstream in(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    {
        std::ofstream out(tmp("pieces_cut.ply"), std::ios::binary);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size() - 1000));
    }
    CHECK_THROWS_WITH(read_ply(tmp("pieces_cut.ply")), Catch::Contains("pieces_cut.ply") && Catch::Contains("truncated"));
}

TEST_CASE("write_ply then read_ply: opacity and scale precision through float32 logit / log", "[ply]") {
    // float32 on disk cannot hold every float32 scale exactly as a log: there are about 4x fewer
    // floats in log space [-13.8, -1] than scales in [1e-6, 1/e]. The writer stores the float L
    // whose decode is nearest, so the error is at most half the decode gap. Exactly:
    //   bit-exact for scales in [1/e, e] and opacities in [0.25, 1];
    //   at most 8 ulp for scales in [1e-6, 1e3] and opacities in [1e-6, 1] (|L| < 16).
    const std::size_t n = 100000;
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> log_scale(std::log(1e-6), std::log(1e3));
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::uniform_real_distribution<double> log_opacity(std::log(1e-6), 0.0);
    GaussianCloud c(n, 0);
    for (auto& v : c.scales) v = static_cast<float>(std::exp(log_scale(rng)));
    for (std::size_t i = 0; i < n; ++i) {
        float p;
        if (i % 2 == 0) {
            do p = unit(rng); while (p <= 0.0f);  // uniform in (0, 1)
        } else {
            p = static_cast<float>(std::exp(log_opacity(rng)));  // many decades near 0
        }
        c.opacities[i] = p;
    }
    // The ends of the ranges and the values that map to infinities.
    c.opacities[0] = 0.0f;
    c.opacities[1] = 1.0f;
    c.opacities[2] = std::nextafter(1.0f, 0.0f);
    c.opacities[3] = 0.25f;
    c.scales[0] = 0.0f;
    c.scales[1] = 1.0f;
    c.scales[2] = 1e-6f;
    c.scales[3] = 1e3f;

    const std::string path = tmp("precision.ply");
    write_ply(path, c);
    const GaussianCloud r = read_ply(path);
    REQUIRE(r.size() == n);
    CHECK(r.opacities[0] == 0.0f);
    CHECK(r.opacities[1] == 1.0f);
    CHECK(r.scales[0] == 0.0f);

    long max_opacity = 0, max_scale = 0;
    std::size_t exact_region_misses = 0, bound_misses = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double p = c.opacities[i];
        const long dp = ulp_distance(c.opacities[i], r.opacities[i]);
        max_opacity = std::max(max_opacity, dp);
        if (p > 0.0 && p < 1.0) {
            const double L = std::log(p) - std::log1p(-p);
            if (dp > allowed_ulps(p, L, p * (1.0 - p))) ++bound_misses;
        }
        if (p >= 0.25 && dp != 0) ++exact_region_misses;
        for (int a = 0; a < 3; ++a) {
            const double s = c.scales[3 * i + a];
            const long ds = ulp_distance(c.scales[3 * i + a], r.scales[3 * i + a]);
            max_scale = std::max(max_scale, ds);
            if (s > 0.0 && ds > allowed_ulps(s, std::log(s), s)) ++bound_misses;
            if (s > 0.0 && std::fabs(std::log(s)) <= 1.0 && ds != 0) ++exact_region_misses;
        }
    }
    INFO("max opacity error " << max_opacity << " ulp, max scale error " << max_scale << " ulp");
    CHECK(bound_misses == 0);
    CHECK(exact_region_misses == 0);
    CHECK(max_opacity <= 8);
    CHECK(max_scale <= 8);
}

TEST_CASE("write_ply writes the INRIA layout", "[ply]") {
    GaussianCloud c = random_cloud(5, 2, true, 1, 3);  // K = 9: 24 f_rest
    const std::string path = tmp("layout.ply");
    write_ply(path, c);
    const std::string file = read_file(path);

    std::string expected = "ply\nformat binary_little_endian 1.0\nelement vertex 5\n";
    for (const char* p : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
        expected += std::string("property float ") + p + "\n";
    for (int k = 0; k < 24; ++k) expected += "property float f_rest_" + std::to_string(k) + "\n";
    for (const char* p : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
                          "confidence", "extra_0"})
        expected += std::string("property float ") + p + "\n";
    expected += "end_header\n";
    REQUIRE(file.substr(0, expected.size()) == expected);

    const std::size_t floats = 9 + 24 + 8 + 2;
    REQUIRE(file.size() == expected.size() + 5 * floats * 4);
    for (std::size_t i = 0; i < 5; ++i) {
        auto at = [&](std::size_t k) {
            const unsigned char* b =
                reinterpret_cast<const unsigned char*>(file.data() + expected.size() + (i * floats + k) * 4);
            const std::uint32_t u = b[0] | (b[1] << 8) | (b[2] << 16) | (static_cast<std::uint32_t>(b[3]) << 24);
            float v;
            std::memcpy(&v, &u, 4);
            return v;
        };
        for (int a = 0; a < 3; ++a) CHECK(bits(at(a)) == bits(c.means[3 * i + a]));
        for (int a = 3; a < 6; ++a) CHECK(at(a) == 0.0f);
        const float* sh = c.sh.data() + i * 9 * 3;
        for (int ch = 0; ch < 3; ++ch) CHECK(bits(at(6 + ch)) == bits(sh[ch]));
        // Channel-major: all 8 higher-band coefficients of R, then G, then B.
        for (int ch = 0; ch < 3; ++ch)
            for (int j = 0; j < 8; ++j) CHECK(bits(at(9 + ch * 8 + j)) == bits(sh[3 * (j + 1) + ch]));
        // Logit and log: within one float step of the exact double value.
        const double p = c.opacities[i];
        CHECK(at(33) == Approx(std::log(p / (1.0 - p))).epsilon(1e-6).margin(1e-6));
        for (int a = 0; a < 3; ++a) CHECK(at(34 + a) == Approx(std::log(c.scales[3 * i + a])).epsilon(1e-6).margin(1e-6));
        for (int a = 0; a < 4; ++a) CHECK(bits(at(37 + a)) == bits(c.rotations[4 * i + a]));
        CHECK(bits(at(41)) == bits(c.confidence[i]));
        CHECK(bits(at(42)) == bits(c.extras[0].values[i]));
    }
}

TEST_CASE("read_ply: a hand-written ASCII file", "[ply]") {
    // Degree 1 (9 f_rest), an element before the vertices and one after (both with lists),
    // properties in a non-standard order, comments, obj_info, an integer extra and confidence.
    const std::string text =
        "ply\n"
        "format ascii 1.0\n"
        "comment written by hand for test_ply.cpp\n"
        "obj_info generated for the tests\n"
        "element camera 2\n"
        "property float fx\n"
        "property list uchar int ids\n"
        "element vertex 2\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property float opacity\n"
        "property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n"
        "property float f_rest_0\nproperty float f_rest_1\nproperty float f_rest_2\n"
        "property float f_rest_3\nproperty float f_rest_4\nproperty float f_rest_5\n"
        "property float f_rest_6\nproperty float f_rest_7\nproperty float f_rest_8\n"
        "property double scale_0\nproperty float scale_1\nproperty float scale_2\n"
        "property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n"
        "property uchar label\n"
        "property float confidence\n"
        "element face 1\n"
        "property list uchar int vertex_indices\n"
        "end_header\n"
        "500 3 1 2 3\n"
        "600 0\n"
        "1.5 -2 +3e2  0 0 1  0  0.1 0.2 0.3  10 11 12 13 14 15 16 17 18  0 0.6931471805599453 -0.6931471805599453  1 0 0 0  7 0.25\n"
        "\t-1 0.5 0 0 0 0 -1.0986122886681098 1 2 3 0 0 0 0 0 0 0 0 0 -1 -inf inf 0.5 0.5 0.5 0.5 255 -3.5 \n"
        "3 0 1 2\n";

    auto check = [](const GaussianCloud& c) {
        REQUIRE(c.size() == 2);
        REQUIRE(c.sh_degree == 1);
        // Means as written.
        CHECK(c.means == std::vector<float>{1.5f, -2.0f, 300.0f, -1.0f, 0.5f, 0.0f});
        // Opacity logit 0 -> 0.5; -ln 3 -> 1/4.
        CHECK(c.opacities[0] == 0.5f);
        CHECK(c.opacities[1] == 0.25f);
        // Scales: log 0 -> 1, ln 2 -> 2, -ln 2 -> 1/2; -inf -> 0, +inf -> inf; -1 -> 1/e.
        CHECK(c.scales[0] == 1.0f);
        CHECK(c.scales[1] == 2.0f);
        CHECK(c.scales[2] == 0.5f);
        CHECK(c.scales[3] == static_cast<float>(std::exp(-1.0)));
        CHECK(c.scales[4] == 0.0f);
        CHECK(std::isinf(c.scales[5]));
        // SH: f_rest_{c*3+j} is coefficient j+1 of channel c.
        const std::vector<float> sh0{0.1f, 0.2f, 0.3f, 10, 13, 16, 11, 14, 17, 12, 15, 18};
        CHECK(std::vector<float>(c.sh.begin(), c.sh.begin() + 12) == sh0);
        CHECK(c.sh[12] == 1.0f);
        CHECK(c.sh[13] == 2.0f);
        CHECK(c.sh[14] == 3.0f);
        CHECK(c.rotations == std::vector<float>{1, 0, 0, 0, 0.5f, 0.5f, 0.5f, 0.5f});
        REQUIRE(c.extras.size() == 1);
        CHECK(c.extras[0].name == "label");
        CHECK(c.extras[0].values == std::vector<float>{7.0f, 255.0f});
        CHECK(c.confidence == std::vector<float>{0.25f, -3.5f});
    };
    const std::string path = tmp("hand.ply");
    write_file(path, text);
    check(read_ply(path));

    SECTION("the same file with CRLF line ends") {
        std::string crlf;
        for (char ch : text) crlf += ch == '\n' ? std::string("\r\n") : std::string(1, ch);
        const std::string p = tmp("hand_crlf.ply");
        write_file(p, crlf);
        check(read_ply(p));
    }
}

TEST_CASE("read_ply: a big-endian file with every PLY scalar type", "[ply]") {
    Body b;
    b.big = true;
    std::string header =
        "ply\nformat binary_big_endian 1.0\nelement vertex 2\n"
        "property double x\nproperty float y\nproperty float64 z\n"
        "property float32 f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\n"
        "property float opacity\nproperty double scale_0\nproperty float scale_1\nproperty float scale_2\n"
        "property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n"
        "property char e_char\nproperty uchar e_uchar\nproperty short e_short\nproperty ushort e_ushort\n"
        "property int e_int\nproperty uint e_uint\nproperty int8 e_int8\nproperty uint8 e_uint8\n"
        "property int16 e_int16\nproperty uint16 e_uint16\nproperty int32 e_int32\nproperty uint32 e_uint32\n"
        "end_header\n";
    const double xs[2] = {0.1, -123456.789};
    const float logits[2] = {2.0f, -0.5f};
    const double log_scales[2] = {-3.25, 0.125};
    for (int i = 0; i < 2; ++i) {
        b.put<double>(xs[i]);
        b.put<float>(1.25f * i);
        b.put<double>(-7.0 + i);
        for (int ch = 0; ch < 3; ++ch) b.put<float>(0.5f * ch - i);
        b.put<float>(logits[i]);
        b.put<double>(log_scales[i]);
        b.put<float>(0.0f);
        b.put<float>(1.0f);
        for (int a = 0; a < 4; ++a) b.put<float>(a + 10.0f * i);
        b.put<std::int8_t>(static_cast<std::int8_t>(-5 - i));
        b.put<std::uint8_t>(250);
        b.put<std::int16_t>(-1234);
        b.put<std::uint16_t>(60000);
        b.put<std::int32_t>(-100000);
        b.put<std::uint32_t>(4000000000u);
        b.put<std::int8_t>(-128);
        b.put<std::uint8_t>(255);
        b.put<std::int16_t>(-32768);
        b.put<std::uint16_t>(65535);
        b.put<std::int32_t>(std::numeric_limits<std::int32_t>::min());
        b.put<std::uint32_t>(7);
    }
    const std::string path = tmp("big_endian.ply");
    write_file(path, header + b.bytes);
    const GaussianCloud c = read_ply(path);
    REQUIRE(c.size() == 2);
    REQUIRE(c.sh_degree == 0);
    for (int i = 0; i < 2; ++i) {
        CHECK(c.means[3 * i + 0] == static_cast<float>(xs[i]));
        CHECK(c.means[3 * i + 1] == 1.25f * i);
        CHECK(c.means[3 * i + 2] == static_cast<float>(-7.0 + i));
        for (int ch = 0; ch < 3; ++ch) CHECK(c.sh[3 * i + ch] == 0.5f * ch - i);
        CHECK(c.opacities[i] == static_cast<float>(sigmoid(logits[i])));
        CHECK(c.scales[3 * i + 0] == static_cast<float>(std::exp(log_scales[i])));
        CHECK(c.scales[3 * i + 1] == 1.0f);
        CHECK(c.scales[3 * i + 2] == static_cast<float>(std::exp(1.0)));
        for (int a = 0; a < 4; ++a) CHECK(c.rotations[4 * i + a] == a + 10.0f * i);
    }
    const std::pair<const char*, std::vector<float>> extras[] = {
        {"e_char", {-5, -6}},
        {"e_uchar", {250, 250}},
        {"e_short", {-1234, -1234}},
        {"e_ushort", {60000, 60000}},
        {"e_int", {-100000, -100000}},
        {"e_uint", {4000000000.0f, 4000000000.0f}},
        {"e_int8", {-128, -128}},
        {"e_uint8", {255, 255}},
        {"e_int16", {-32768, -32768}},
        {"e_uint16", {65535, 65535}},
        {"e_int32", {-2147483648.0f, -2147483648.0f}},
        {"e_uint32", {7, 7}},
    };
    REQUIRE(c.extras.size() == 12);
    for (const auto& [name, values] : extras) {
        const auto* e = c.find_extra(name);
        REQUIRE(e != nullptr);
        CHECK(e->values == values);
    }
}

TEST_CASE("read_ply: shuffled property order, double properties and other elements", "[ply]") {
    const GaussianCloud ref = random_cloud(40, 3, true, 1, 21);
    const int K = 16;
    // Every property of the cloud in a shuffled order, half of them as doubles.
    struct Prop { std::string name; bool dbl; };
    std::vector<Prop> props;
    for (const char* p : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0",
                          "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3", "confidence", "extra_0"})
        props.push_back({p, false});
    for (int k = 0; k < 45; ++k) props.push_back({"f_rest_" + std::to_string(k), false});
    std::mt19937 rng(5);
    std::shuffle(props.begin(), props.end(), rng);
    for (std::size_t k = 0; k < props.size(); ++k) props[k].dbl = (k % 2 == 0);

    // On-disk value of property `name` for row i, in double (the disk type decides the rounding).
    auto disk_value = [&](const std::string& name, std::size_t i) -> double {
        if (name == "x") return ref.means[3 * i];
        if (name == "y") return ref.means[3 * i + 1];
        if (name == "z") return ref.means[3 * i + 2];
        if (name == "nx" || name == "ny" || name == "nz") return 0.5;
        if (name.rfind("f_dc_", 0) == 0) return ref.sh[i * K * 3 + (name[5] - '0')];
        if (name.rfind("f_rest_", 0) == 0) {
            const int idx = std::stoi(name.substr(7));
            return ref.sh[i * K * 3 + 3 * (idx % (K - 1) + 1) + idx / (K - 1)];
        }
        if (name == "opacity") {
            const double p = ref.opacities[i];
            return std::log(p) - std::log1p(-p);
        }
        if (name.rfind("scale_", 0) == 0) return std::log(static_cast<double>(ref.scales[3 * i + (name[6] - '0')]));
        if (name.rfind("rot_", 0) == 0) return ref.rotations[4 * i + (name[4] - '0')];
        if (name == "confidence") return ref.confidence[i];
        return ref.extras[0].values[i];
    };

    // A fixed-size element before the vertices, a list element before them, and a fixed-size
    // element after them; all must be skipped.
    std::string header = "ply\nformat binary_little_endian 1.0\n"
                         "element fixed_before 3\nproperty double a\nproperty uchar b\n"
                         "element lists_before 2\nproperty list uint short items\nproperty float w\n"
                         "element vertex 40\n";
    for (const auto& p : props) header += std::string("property ") + (p.dbl ? "double " : "float ") + p.name + "\n";
    header += "element fixed_after 2\nproperty int k\nend_header\n";
    Body b;
    for (int r = 0; r < 3; ++r) {
        b.put<double>(r);
        b.put<std::uint8_t>(9);
    }
    b.put<std::uint32_t>(3);
    for (int k = 0; k < 3; ++k) b.put<std::int16_t>(static_cast<std::int16_t>(k));
    b.put<float>(1.0f);
    b.put<std::uint32_t>(0);
    b.put<float>(2.0f);
    for (std::size_t i = 0; i < ref.size(); ++i) {
        for (const auto& p : props) {
            const double v = disk_value(p.name, i);
            if (p.dbl) b.put<double>(v);
            else b.put<float>(static_cast<float>(v));
        }
    }
    b.put<std::int32_t>(1);
    b.put<std::int32_t>(2);
    const std::string path = tmp("shuffled.ply");
    write_file(path, header + b.bytes);

    const GaussianCloud c = read_ply(path);
    REQUIRE(c.size() == 40);
    REQUIRE(c.sh_degree == 3);
    // Means, SH, rotations, confidence and extras were written from floats: exact either way.
    CHECK(first_bit_mismatch(c.means, ref.means) == -1);
    CHECK(first_bit_mismatch(c.sh, ref.sh) == -1);
    CHECK(first_bit_mismatch(c.rotations, ref.rotations) == -1);
    CHECK(first_bit_mismatch(c.confidence, ref.confidence) == -1);
    REQUIRE(c.extras.size() == 1);
    CHECK(first_bit_mismatch(c.extras[0].values, ref.extras[0].values) == -1);
    // Opacity and scales decode in double from the value on disk, rounded once.
    for (const auto& p : props) {
        for (std::size_t i = 0; i < ref.size(); ++i) {
            const double disk = p.dbl ? disk_value(p.name, i) : static_cast<float>(disk_value(p.name, i));
            if (p.name == "opacity") {
                CHECK(c.opacities[i] == static_cast<float>(sigmoid(disk)));
                // A double logit is precise enough to give the opacity back exactly.
                if (p.dbl) CHECK(c.opacities[i] == ref.opacities[i]);
            } else if (p.name.rfind("scale_", 0) == 0) {
                const int a = p.name[6] - '0';
                CHECK(c.scales[3 * i + a] == static_cast<float>(std::exp(disk)));
                if (p.dbl) CHECK(c.scales[3 * i + a] == ref.scales[3 * i + a]);
            }
        }
    }
}

TEST_CASE("write_ply then read_ply: an empty cloud", "[ply]") {
    const GaussianCloud c(0, 2);
    const std::string path = tmp("empty_cloud.ply");
    write_ply(path, c);
    const GaussianCloud r = read_ply(path);
    CHECK(r.size() == 0);
    CHECK(r.sh_degree == 2);
    CHECK(consistent_shapes(r));
}

TEST_CASE("read_ply: a corrupted corpus gives a valid cloud or an IOError, nothing else", "[ply]") {
    // A valid file: a fixed-size element before and after the vertices, so that every
    // truncation changes the sizes the header promises.
    const GaussianCloud ref = random_cloud(16, 1, true, 2, 99);
    const std::string good_path = tmp("corpus_good.ply");
    write_ply(good_path, ref);
    const std::string written = read_file(good_path);
    const std::string marker = "element vertex";
    std::string file = written;
    file.insert(file.find(marker), "element before 2\nproperty short s\n");
    file.insert(file.find("end_header\n"), "element after 3\nproperty uchar t\n");
    {
        const std::size_t data = file.find("end_header\n") + 11;
        file.insert(data, std::string("\x01\x00\x02\x00", 4));
        file += std::string("\x07\x08\x09", 3);
    }
    write_file(good_path, file);
    {
        const GaussianCloud c = read_ply(good_path);
        require_same_shapes(ref, c);
        CHECK(first_bit_mismatch(c.sh, ref.sh) == -1);
    }
    const std::size_t header_end = file.find("end_header\n") + 11;

    SECTION("truncation at every header line boundary, inside the header and in the data") {
        std::vector<std::size_t> cuts{0, 1, 2, 3};
        for (std::size_t k = 0; k < header_end; ++k)
            if (file[k] == '\n') cuts.push_back(k + 1);
        std::mt19937 rng(1234);
        std::uniform_int_distribution<std::size_t> offset(1, file.size() - 1);
        for (int k = 0; k < 50; ++k) cuts.push_back(offset(rng));
        cuts.push_back(file.size() - 1);
        for (std::size_t cut : cuts) {
            INFO("truncated at byte " << cut << " of " << file.size());
            const std::string path = tmp("corpus_cut.ply");
            write_file(path, file.substr(0, cut));
            // Every prefix lacks data the header promises (or the header itself): an error.
            CHECK_FALSE(read_succeeds_or_io_error(path));
        }
    }

    SECTION("200 random bit flips") {
        std::mt19937 rng(4321);
        std::uniform_int_distribution<std::size_t> byte(0, file.size() - 1);
        std::uniform_int_distribution<int> bit(0, 7);
        std::size_t read_ok = 0;
        for (int k = 0; k < 200; ++k) {
            std::string bad = file;
            // Half of the flips land in the header, where they do the most damage.
            const std::size_t at = (k % 2 == 0) ? byte(rng) % header_end : byte(rng);
            bad[at] = static_cast<char>(bad[at] ^ (1 << bit(rng)));
            INFO("flip " << k << " at byte " << at);
            const std::string path = tmp("corpus_flip.ply");
            write_file(path, bad);
            read_ok += read_succeeds_or_io_error(path) ? 1 : 0;
        }
        // Flips in the data section read back (as other values); header flips mostly fail.
        CHECK(read_ok > 0);
        CHECK(read_ok < 200);
    }

    SECTION("the same for an ASCII file: truncations and random byte changes") {
        std::string text = "ply\nformat ascii 1.0\nelement vertex 3\n";
        for (const char* p : {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
                              "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
            text += std::string("property float ") + p + "\n";
        text += "end_header\n";
        const std::size_t text_header_end = text.size();
        for (int i = 0; i < 3; ++i) text += "1.25 -2.5 3 0.1 0.2 0.3 0.5 -1 -2 -3 1 0 0 0\n";
        const std::string path = tmp("corpus_ascii.ply");
        write_file(path, text);
        REQUIRE(read_ply(path).size() == 3);
        for (std::size_t cut = 0; cut + 1 < text.size(); cut += 3) {
            INFO("ASCII truncated at byte " << cut);
            write_file(path, text.substr(0, cut));
            // Cutting the last row short at a token boundary can leave a complete-looking row
            // with fewer tokens: still an error. Only the final newline is optional.
            CHECK_FALSE(read_succeeds_or_io_error(path));
        }
        std::mt19937 rng(77);
        const char replacements[] = {'x', ' ', '\n', '-', '.', 'e', '\0', '9'};
        for (int k = 0; k < 100; ++k) {
            std::string bad = text;
            const std::size_t at = std::uniform_int_distribution<std::size_t>(0, text.size() - 1)(rng);
            bad[at] = replacements[k % 8];
            INFO("ASCII byte " << at << " (header ends at " << text_header_end << ") set to code "
                               << static_cast<int>(replacements[k % 8]));
            write_file(path, bad);
            read_succeeds_or_io_error(path);
        }
    }
}

namespace {

// A minimal degree-0 header with the given format, vertex count and property lines.
const char* const kRequired[] = {"x",       "y",       "z",       "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                 "scale_0", "scale_1", "scale_2", "rot_0",  "rot_1",  "rot_2",  "rot_3"};

std::string header(const std::string& format, const std::string& count, const std::string& extra_props = "",
                   const char* skip = nullptr) {
    std::string h = "ply\nformat " + format + " 1.0\nelement vertex " + count + "\n";
    for (const char* p : kRequired)
        if (!skip || std::string(p) != skip) h += std::string("property float ") + p + "\n";
    return h + extra_props + "end_header\n";
}

std::string ascii_row(int values = 14) {
    std::string row;
    for (int k = 0; k < values; ++k) row += (k ? " " : "") + std::to_string(k % 3);
    return row + "\n";
}

std::string binary_rows(int rows, int values = 14) {
    Body b;
    for (int k = 0; k < rows * values; ++k) b.put<float>(0.5f);
    return b.bytes;
}

// read_ply(path) must throw an IOError whose message names the file and contains `what`.
void require_io_error(const std::string& name, const std::string& contents, const std::string& what) {
    const std::string path = tmp("bad_" + name + ".ply");
    write_file(path, contents);
    INFO("case " << name);
    REQUIRE_THROWS_AS(read_ply(path), IOError);
    REQUIRE_THROWS_WITH(read_ply(path), Contains(path) && Contains(what));
}

}  // namespace

TEST_CASE("read_ply: malformed files give an IOError naming the file and the problem", "[ply]") {
    const std::string bin = "binary_little_endian";

    SECTION("not a PLY file") {
        require_io_error("empty", "", "empty file");
        require_io_error("text", "hello world\n", "not a PLY file");
        require_io_error("plyx", "plyx\nformat ascii 1.0\n", "not a PLY file");
        std::string garbage(100000, 'a');  // no newline at all
        require_io_error("no_newline", "ply " + garbage, "not a PLY");
        require_io_error("long_line", "ply\ncomment " + garbage + "\n", "longer than");
        require_io_error("nul", std::string("ply\nform\0at ascii 1.0\n", 22), "NUL byte");
    }
    SECTION("bad headers") {
        require_io_error("unknown_format", header("binary_middle_endian", "1"), "unknown format");
        require_io_error("version", "ply\nformat ascii 2.0\nend_header\n", "unsupported PLY version");
        require_io_error("no_format", "ply\nelement vertex 1\nend_header\n", "element before the format line");
        require_io_error("keyword", "ply\nformat ascii 1.0\nelemnt vertex 1\nend_header\n", "unknown keyword");
        require_io_error("no_end", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "end_header");
        require_io_error("prop_first", "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
                         "property before any element");
        require_io_error("type", header("ascii", "1", "property float16 h\n"), "unknown property type");
        require_io_error("short_property", header("ascii", "1", "property float\n"), "expected \"property");
        require_io_error("count_text", header("ascii", "abc"), "element count");
        require_io_error("count_negative", header("ascii", "-1"), "element count");
        require_io_error("count_too_big", header(bin, "99999999999999999999999"), "element count");
        require_io_error("dup_property", header("ascii", "1", "property float x\n"), "duplicate property \"x\"");
        require_io_error("dup_element", header("ascii", "0", "element vertex 0\n"), "duplicate element");
        require_io_error("no_vertex", "ply\nformat ascii 1.0\nelement face 0\nend_header\n", "no \"vertex\" element");
        require_io_error("list_vertex", header(bin, "1", "property list uchar int ids\n"), "is a list");
        require_io_error("f_rest_count", header(bin, "1", "property float f_rest_0\n"), "1 f_rest properties");
        std::string ten;
        for (int k = 0; k < 10; ++k) ten += "property float f_rest_" + std::to_string(k) + "\n";
        require_io_error("f_rest_ten", header(bin, "1", ten), "10 f_rest properties");
        std::string bad_index;
        for (int k = 0; k < 9; ++k) bad_index += "property float f_rest_" + std::to_string(k == 8 ? 9 : k) + "\n";
        require_io_error("f_rest_index", header(bin, "1", bad_index), "f_rest_9");
        std::string leading_zero;
        for (int k = 0; k < 9; ++k) leading_zero += "property float f_rest_" + std::string(k == 1 ? "01" : std::to_string(k)) + "\n";
        require_io_error("f_rest_leading_zero", header(bin, "1", leading_zero), "f_rest_01");
        // from_chars takes a sign: a signed index must not become a negative SH offset.
        for (const char* sign : {"-", "+"}) {
            std::string signed_index;
            for (int k = 0; k < 9; ++k)
                signed_index += "property float f_rest_" + (k == 8 ? std::string(sign) + "1" : std::to_string(k)) + "\n";
            require_io_error(std::string("f_rest_sign") + (sign[0] == '-' ? "m" : "p"),
                             header(bin, "1", signed_index) + binary_rows(1, 23), std::string("f_rest_") + sign + "1");
        }
    }
    SECTION("each missing required property is named") {
        for (const char* p : kRequired)
            require_io_error(std::string("missing_") + p, header(bin, "1", "", p) + binary_rows(1, 13),
                             std::string("no \"") + p + "\" property");
    }
    SECTION("counts that do not match the data") {
        require_io_error("absurd_count", header(bin, "1000000000000000000") + binary_rows(2), "bad vertex count");
        // count * 56 bytes overflows 64 bits: must still be caught, not wrapped.
        require_io_error("overflow_count", header(bin, "18446744073709551615") + binary_rows(2), "bad vertex count");
        require_io_error("overflow_count_big", header("binary_big_endian", "329406144173384851") + binary_rows(2),
                         "bad vertex count");
        require_io_error("short_data", header(bin, "5") + binary_rows(4), "bad vertex count");
        require_io_error("extra_data", header(bin, "3") + binary_rows(4), "do not match the data");
        require_io_error("cut_row", header(bin, "2") + binary_rows(2).substr(0, 100), "bad vertex count");
        require_io_error("before_too_big", "ply\nformat binary_little_endian 1.0\nelement cams 1000000000000\n"
                                           "property double f\n" + header(bin, "1").substr(36) + binary_rows(1),
                         "does not fit");
        require_io_error("ascii_absurd_count", header("ascii", "1000000000000000000") + ascii_row(), "1 of 1000000000000000000 rows");
        require_io_error("ascii_short", header("ascii", "3") + ascii_row() + ascii_row(), "2 of 3 rows");
        require_io_error("ascii_extra", header("ascii", "1") + ascii_row() + ascii_row(), "does not match the data");
    }
    SECTION("bad ASCII values") {
        require_io_error("ascii_word", header("ascii", "1") + "0 1 abc 0 1 2 0 1 2 0 1 2 0 1\n", "\"abc\" is not a valid value of property \"z\"");
        require_io_error("ascii_suffix", header("ascii", "1") + "0 1 2 0 1 2x 0 1 2 0 1 2 0 1\n", "\"2x\"");
        require_io_error("ascii_two_signs", header("ascii", "1") + "0 1 2 0 1 2 0 1 +-2 0 1 2 0 1\n", "\"+-2\"");
        require_io_error("ascii_few", header("ascii", "1") + ascii_row(13), "has 13 values, expected 14");
        require_io_error("ascii_many", header("ascii", "1") + ascii_row(15), "has 15 values, expected 14");
        require_io_error("ascii_uchar_range", header("ascii", "1", "property uchar u\n") + "0 1 2 0 1 2 0 1 2 0 1 2 0 1 300\n",
                         "\"300\" is not a valid value of property \"u\"");
        require_io_error("ascii_int_fraction", header("ascii", "1", "property int u\n") + "0 1 2 0 1 2 0 1 2 0 1 2 0 1 1.5\n",
                         "\"1.5\"");
    }
    SECTION("files that cannot be read") {
        const std::string missing = tmp("does_not_exist.ply");
        REQUIRE_THROWS_WITH(read_ply(missing), Contains(missing) && Contains("cannot open"));
        const std::string dir = AVSPLAT_TEST_TMP;
        REQUIRE_THROWS_AS(read_ply(dir), IOError);
        REQUIRE_THROWS_WITH(read_ply(dir), Contains(dir));
    }
}

TEST_CASE("read_ply: tolerated variants of valid files", "[ply]") {
    // No trailing newline after the last ASCII row; blank lines; extra spaces and tabs.
    const std::string p1 = tmp("ascii_no_newline.ply");
    write_file(p1, header("ascii", "2") + "  0 1 2 0 1 2 0 1 2 0 1 2 0 1\n\n\t0 1 2 0 1 2 0 1 2 0 1 2 0 1");
    CHECK(read_ply(p1).size() == 2);
    // A vertex-free file ending right at end_header.
    const std::string p2 = tmp("no_vertices.ply");
    std::string h = header("binary_little_endian", "0");
    h.pop_back();
    write_file(p2, h);
    CHECK(read_ply(p2).size() == 0);
    // A float out of float32 range in an ASCII file rounds as a binary reader would.
    const std::string p3 = tmp("ascii_range.ply");
    write_file(p3, header("ascii", "1") + "1e-50 1e40 -1e40 0 0 0 0 0 0 0 1 0 0 0\n");
    const GaussianCloud c = read_ply(p3);
    CHECK(c.means[0] == 0.0f);
    CHECK(c.means[1] == std::numeric_limits<float>::infinity());
    CHECK(c.means[2] == -std::numeric_limits<float>::infinity());
}

TEST_CASE("write_ply: invalid clouds and unwritable paths", "[ply]") {
    GaussianCloud c = random_cloud(4, 1, false, 0, 1);
    const std::string path = tmp("write_errors.ply");

    GaussianCloud bad_shape = c;
    bad_shape.means.pop_back();
    CHECK_THROWS_AS(write_ply(path, bad_shape), std::invalid_argument);

    GaussianCloud nan = c;
    nan.sh[5] = std::numeric_limits<float>::quiet_NaN();
    CHECK_THROWS_WITH(write_ply(path, nan), Contains("sh"));
    CHECK_THROWS_AS(write_ply(path, nan), std::invalid_argument);

    for (const char* name : {"opacity", "f_rest_3", "x", "confidence", "nx"}) {
        GaussianCloud clash = c;
        clash.set_extra(name, std::vector<float>(4, 1.0f));
        CHECK_THROWS_WITH(write_ply(path, clash), Contains(name) && Contains("3DGS PLY property"));
    }
    GaussianCloud spaced = c;
    spaced.set_extra("my value", std::vector<float>(4, 1.0f));
    CHECK_THROWS_WITH(write_ply(path, spaced), Contains("my value") && Contains("spaces"));

    const std::string nowhere = std::string(AVSPLAT_TEST_TMP) + "/no_such_dir/out.ply";
    CHECK_THROWS_AS(write_ply(nowhere, c), IOError);
    CHECK_THROWS_WITH(write_ply(nowhere, c), Contains(nowhere));
}

TEST_CASE("read_ply: elements after the vertices must be there in full", "[ply]") {
    // A header declaring `element face 5` with no face data was accepted (the list rows were not
    // walked); now it is a truncated file, in binary and in ASCII.
    const std::string face = "element face 5\nproperty list uchar int vertex_indices\n";
    const std::string bin = "binary_little_endian";
    require_io_error("face_no_data_bin", header(bin, "1", face) + binary_rows(1), "element \"face\" (5 rows)");
    require_io_error("face_no_data_ascii", header("ascii", "1", face) + ascii_row(), "element \"face\" has 0 of 5 rows");
    // Three of five faces, then a cut inside a list.
    Body faces;
    for (int f = 0; f < 3; ++f) {
        faces.put<std::uint8_t>(3);
        for (int v = 0; v < 3; ++v) faces.put<std::int32_t>(0);
    }
    require_io_error("face_three_of_five", header(bin, "1", face) + binary_rows(1) + faces.bytes, "element \"face\"");
    // Bytes after complete face data are reported too.
    Body five;
    for (int f = 0; f < 5; ++f) {
        five.put<std::uint8_t>(3);
        for (int v = 0; v < 3; ++v) five.put<std::int32_t>(0);
    }
    require_io_error("face_trailing", header(bin, "1", face) + binary_rows(1) + five.bytes + "x", "1 bytes after");
    require_io_error("face_extra_line", header("ascii", "1", face) + ascii_row() + "3 0 0 0\n3 0 0 0\n3 0 0 0\n3 0 0 0\n3 0 0 0\n9\n",
                     "after the rows of the last element");
    // Complete face data is read past, in both encodings.
    const std::string good_bin = tmp("face_complete_bin.ply");
    write_file(good_bin, header(bin, "1", face) + binary_rows(1) + five.bytes);
    CHECK(read_ply(good_bin).size() == 1);
    const std::string good_ascii = tmp("face_complete_ascii.ply");
    write_file(good_ascii, header("ascii", "1", face) + ascii_row() + "3 0 0 0\n3 0 0 0\n3 0 0 0\n3 0 0 0\n4 0 0 0 0\n");
    CHECK(read_ply(good_ascii).size() == 1);
}
