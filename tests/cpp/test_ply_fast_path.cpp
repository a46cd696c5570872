// The fast paths of read_ply against the generic ones: the bulk opacity / scale
// decode (AVX2 exp) against the scalar functions, and the fixed-offset transposition of the
// INRIA layout against read_ply_data's columns (the generic PLY layer, values in double) turned
// into Gaussians here, on random layouts: property order shuffled or standard, normals or none,
// SH degree 0..3, extra properties, double and integer columns, either endianness, one thread or
// two. Every comparison is of bits.
#include "avsplat/core/error.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/ply_data.h"
#include "io/ply/gaussian_activations.h"
#include "io/ply/ply_format.h"

#include <catch2/catch.hpp>

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

using avsplat::GaussianCloud;
using avsplat::IOError;
using avsplat::PlyType;

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/ply_fast_" + name; }

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

// The 3DGS activations as the INRIA code defines them, in double, rounded once.
float ref_scale(double s) { return static_cast<float>(std::exp(s)); }
float ref_opacity(double l) {
    return static_cast<float>(l >= 0 ? 1.0 / (1.0 + std::exp(-l)) : std::exp(l) / (1.0 + std::exp(l)));
}

// Random floats: typical values, the whole range of exponents, and the edge cases.
std::vector<float> activation_inputs(std::mt19937& rng) {
    std::vector<float> v = {0.0f, -0.0f, 1.0f, -1.0f, 80.0f, -80.0f, std::nextafter(80.0f, 100.0f),
                            std::nextafter(-80.0f, -100.0f), 88.7f, 88.8f, -103.9f, -104.0f, -150.0f, 1e30f,
                            -1e30f, std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                            std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::denorm_min(),
                            -std::numeric_limits<float>::denorm_min(), std::numeric_limits<float>::max(),
                            std::numeric_limits<float>::lowest()};
    std::uniform_real_distribution<float> typical(-12.0f, 12.0f), wide(-100.0f, 100.0f);
    std::uniform_int_distribution<std::uint32_t> any;
    for (int k = 0; k < 1500000; ++k) v.push_back(typical(rng));
    for (int k = 0; k < 500000; ++k) v.push_back(wide(rng));
    for (int k = 0; k < 200000; ++k) {
        const std::uint32_t b = any(rng);
        float f;
        std::memcpy(&f, &b, 4);
        v.push_back(f);
    }
    return v;
}

}  // namespace

TEST_CASE("encode_scales and encode_opacities give the scalar functions' bits", "[ply]") {
    std::mt19937 rng(1818);
    std::vector<float> in = activation_inputs(rng);
    // What the writer meets: scales log-uniform over [1e-9, 1e5], opacities in (0, 1) with both
    // ends and the middle (where the logit's two logs cancel) dense, the bulk path's range limits.
    std::uniform_real_distribution<double> log_scale(std::log(1e-9), std::log(1e5)), unit(0.0, 1.0),
        near_half(0.5 - 1e-4, 0.5 + 1e-4);
    for (int k = 0; k < 1000000; ++k) in.push_back(float(std::exp(log_scale(rng))));
    for (int k = 0; k < 1000000; ++k) in.push_back(float(unit(rng)));
    for (int k = 0; k < 200000; ++k) in.push_back(float(near_half(rng)));
    for (int k = 0; k < 200000; ++k) in.push_back(float(std::exp(-30.0 * unit(rng))));         // down to 1e-13
    for (int k = 0; k < 200000; ++k) in.push_back(float(1.0 - std::exp(-16.0 * unit(rng))));  // up to 1 - 1e-7
    float above_half = 0.5f;
    for (int k = 0; k < 64; ++k) {  // the floats just above 1/2 and just below 1
        in.push_back(above_half = std::nextafter(above_half, 1.0f));
        in.push_back(std::nextafter(1.0f, 0.0f) - float(k) * 0x1p-24f);
    }
    for (float v : {0x1p-30f, std::nextafter(0x1p-30f, 0.0f), std::nextafter(0x1p-30f, 1.0f), 0x1p-126f,
                    std::numeric_limits<float>::min(), std::nextafter(std::numeric_limits<float>::max(), 0.0f)})
        in.push_back(v);
    for (std::size_t drop : {0u, 1u, 2u, 3u}) {
        const std::vector<float> x(in.begin() + static_cast<long>(drop), in.end());
        std::vector<float> s(x.size()), o(x.size()), s_ref(x.size()), o_ref(x.size());
        avsplat::ply::encode_scales(x.data(), s.data(), x.size());
        avsplat::ply::encode_opacities(x.data(), o.data(), x.size());
        for (std::size_t i = 0; i < x.size(); ++i) {
            s_ref[i] = avsplat::ply::encode_scale(x[i]);
            o_ref[i] = avsplat::ply::encode_opacity(x[i]);
        }
        INFO("dropped " << drop);
        const long bad_s = first_bit_mismatch(s, s_ref), bad_o = first_bit_mismatch(o, o_ref);
        auto at = [&](long i, const std::vector<float>& got, const std::vector<float>& want) {
            if (i < 0) return std::string("none");
            const std::size_t j = std::size_t(i);
            return std::to_string(j) + ": input " + std::to_string(x[j]) + ", bulk " + std::to_string(got[j]) +
                   ", scalar " + std::to_string(want[j]);
        };
        INFO("first scale mismatch " << at(bad_s, s, s_ref) << "; first opacity mismatch " << at(bad_o, o, o_ref));
        CHECK(bad_s == -1);
        CHECK(bad_o == -1);
    }
    // The scalar functions are the logs in double, rounded once (the writer's contract).
    for (std::size_t i = 0; i < in.size(); i += 7) {
        const double v = in[i];
        if (!(v > 0.0 && v < 1.0)) continue;
        REQUIRE(bits(avsplat::ply::encode_scale(in[i])) == bits(float(std::log(v))));
        REQUIRE(bits(avsplat::ply::encode_opacity(in[i])) == bits(float(std::log(v) - std::log1p(-v))));
    }
}

TEST_CASE("decode_scales and decode_opacities give the scalar functions' bits", "[ply]") {
    std::mt19937 rng(18);
    const std::vector<float> in = activation_inputs(rng);
    // Every length mod 4 (the vector width), every alignment of the tail.
    for (std::size_t drop : {0u, 1u, 2u, 3u}) {
        const std::vector<float> x(in.begin() + static_cast<long>(drop), in.end());
        std::vector<float> s = x, o = x;
        avsplat::ply::decode_scales(s.data(), s.size());
        avsplat::ply::decode_opacities(o.data(), o.size());
        std::vector<float> s_ref(x.size()), o_ref(x.size());
        for (std::size_t i = 0; i < x.size(); ++i) {
            s_ref[i] = avsplat::ply::decode_scale(x[i]);
            o_ref[i] = avsplat::ply::decode_opacity(x[i]);
        }
        INFO("dropped " << drop);
        CHECK(first_bit_mismatch(s, s_ref) == -1);
        CHECK(first_bit_mismatch(o, o_ref) == -1);
    }
    // The scalar functions are the INRIA activations (NaN compares by payload-free class).
    for (std::size_t i = 0; i < 100000; ++i) {
        const float x = in[i];
        if (std::isnan(x)) continue;
        REQUIRE(bits(avsplat::ply::decode_scale(x)) == bits(ref_scale(x)));
        REQUIRE(bits(avsplat::ply::decode_opacity(x)) == bits(ref_opacity(x)));
    }
}

namespace {

struct Prop {
    std::string name;
    PlyType type;
};

template <class T>
void put(std::string& out, T v, bool big_endian) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (big_endian) std::reverse(b, b + sizeof(T));
    out.append(reinterpret_cast<const char*>(b), sizeof(T));
}

// A random value of type t, written to `out`.
void put_random(std::string& out, PlyType t, bool big_endian, const std::string& name, std::mt19937& rng) {
    const bool activation = name == "opacity" || name.rfind("scale_", 0) == 0;
    std::uniform_real_distribution<double> real(activation ? -12.0 : -3.0, activation ? 4.0 : 3.0);
    std::uniform_int_distribution<int> pick(0, 999);
    double v = real(rng);
    // Now and then a value the bulk exp leaves to the scalar one.
    if (activation && pick(rng) == 0) v = pick(rng) < 500 ? 95.0 : std::numeric_limits<double>::quiet_NaN();
    std::uniform_int_distribution<std::int64_t> i8(-128, 127), u8(0, 255), i16(-32768, 32767), u16(0, 65535),
        i32(INT32_MIN, INT32_MAX), u32(0, UINT32_MAX);
    switch (t) {
        case PlyType::Int8: return put(out, static_cast<std::int8_t>(i8(rng)), big_endian);
        case PlyType::UInt8: return put(out, static_cast<std::uint8_t>(u8(rng)), big_endian);
        case PlyType::Int16: return put(out, static_cast<std::int16_t>(i16(rng)), big_endian);
        case PlyType::UInt16: return put(out, static_cast<std::uint16_t>(u16(rng)), big_endian);
        case PlyType::Int32: return put(out, static_cast<std::int32_t>(i32(rng)), big_endian);
        case PlyType::UInt32: return put(out, static_cast<std::uint32_t>(u32(rng)), big_endian);
        case PlyType::Float32: return put(out, static_cast<float>(v), big_endian);
        case PlyType::Float64: return put(out, v, big_endian);
    }
}

// The Gaussians of a file, computed from read_ply_data's columns (the generic PLY layer).
GaussianCloud from_columns(const std::string& path) {
    const avsplat::PlyData data = avsplat::read_ply_data(path);
    const avsplat::PlyElement& v = *data.find("vertex");
    const std::size_t n = static_cast<std::size_t>(v.count);
    int rest = 0;
    for (const auto& c : v.columns)
        if (c.name.rfind("f_rest_", 0) == 0) ++rest;
    const int K = rest / 3 + 1;
    GaussianCloud g;
    g.sh_degree = K == 1 ? 0 : K == 4 ? 1 : K == 9 ? 2 : 3;
    g.means.resize(3 * n);
    g.scales.resize(3 * n);
    g.rotations.resize(4 * n);
    g.opacities.resize(n);
    g.sh.resize(3 * K * n);
    for (const auto& c : v.columns) {
        const std::string& name = c.name;
        auto each = [&](auto&& f) {
            for (std::size_t i = 0; i < n; ++i) f(i, c.values[i]);
        };
        if (name == "x" || name == "y" || name == "z") {
            const int a = name[0] - 'x';
            each([&](std::size_t i, double x) { g.means[3 * i + a] = static_cast<float>(x); });
        } else if (name == "nx" || name == "ny" || name == "nz") {
        } else if (name.rfind("f_dc_", 0) == 0) {
            const int ch = name[5] - '0';
            each([&](std::size_t i, double x) { g.sh[3 * K * i + ch] = static_cast<float>(x); });
        } else if (name.rfind("f_rest_", 0) == 0) {
            const int idx = std::stoi(name.substr(7));
            const int ch = idx / (K - 1), j = idx % (K - 1);
            each([&](std::size_t i, double x) { g.sh[3 * K * i + 3 * (j + 1) + ch] = static_cast<float>(x); });
        } else if (name == "opacity") {
            each([&](std::size_t i, double x) { g.opacities[i] = ref_opacity(x); });
        } else if (name.rfind("scale_", 0) == 0) {
            const int a = name[6] - '0';
            each([&](std::size_t i, double x) { g.scales[3 * i + a] = ref_scale(x); });
        } else if (name.rfind("rot_", 0) == 0) {
            const int a = name[4] - '0';
            each([&](std::size_t i, double x) { g.rotations[4 * i + a] = static_cast<float>(x); });
        } else if (name == "confidence") {
            g.confidence.resize(n);
            each([&](std::size_t i, double x) { g.confidence[i] = static_cast<float>(x); });
        } else {
            g.extras.push_back({name, std::vector<float>(n)});
            each([&](std::size_t i, double x) { g.extras.back().values[i] = static_cast<float>(x); });
        }
    }
    return g;
}

void check_same(const GaussianCloud& c, const GaussianCloud& ref) {
    REQUIRE(c.size() == ref.size());
    REQUIRE(c.sh_degree == ref.sh_degree);
    CHECK(first_bit_mismatch(c.means, ref.means) == -1);
    CHECK(first_bit_mismatch(c.sh, ref.sh) == -1);
    CHECK(first_bit_mismatch(c.opacities, ref.opacities) == -1);
    CHECK(first_bit_mismatch(c.scales, ref.scales) == -1);
    CHECK(first_bit_mismatch(c.rotations, ref.rotations) == -1);
    CHECK(first_bit_mismatch(c.confidence, ref.confidence) == -1);
    REQUIRE(c.extras.size() == ref.extras.size());
    for (std::size_t k = 0; k < c.extras.size(); ++k) {
        CHECK(c.extras[k].name == ref.extras[k].name);
        CHECK(first_bit_mismatch(c.extras[k].values, ref.extras[k].values) == -1);
    }
}

// The INRIA layout's properties in file order.
std::vector<std::string> standard_names(int degree, bool normals) {
    std::vector<std::string> names = {"x", "y", "z"};
    if (normals) names.insert(names.end(), {"nx", "ny", "nz"});
    names.insert(names.end(), {"f_dc_0", "f_dc_1", "f_dc_2"});
    const int K = (degree + 1) * (degree + 1);
    for (int k = 0; k < 3 * (K - 1); ++k) names.push_back("f_rest_" + std::to_string(k));
    names.insert(names.end(), {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"});
    return names;
}

std::string ply_file(const std::vector<Prop>& props, std::size_t n, bool big_endian, std::mt19937& rng) {
    std::string s = std::string("ply\nformat ") + (big_endian ? "binary_big_endian" : "binary_little_endian") +
                    " 1.0\nelement vertex " + std::to_string(n) + "\n";
    for (const auto& p : props) s += std::string("property ") + avsplat::ply::type_name(p.type) + " " + p.name + "\n";
    s += "end_header\n";
    for (std::size_t i = 0; i < n; ++i)
        for (const auto& p : props) put_random(s, p.type, big_endian, p.name, rng);
    return s;
}

void write_file(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    REQUIRE(out.good());
}

}  // namespace

TEST_CASE("read_ply on random layouts equals the generic column layer, on one thread or two", "[ply]") {
    std::mt19937 rng(1818);
    const PlyType others[] = {PlyType::Int8,   PlyType::UInt8,  PlyType::Int16,   PlyType::UInt16,
                              PlyType::Int32,  PlyType::UInt32, PlyType::Float64};
    const int threads = omp_get_max_threads();
    for (int trial = 0; trial < 40; ++trial) {
        // Trials 0..7: the INRIA layout itself (degree 0..3, with and without normals), all
        // float32 little endian, as written by every trainer; then random layouts.
        const int degree = trial % 4;
        const bool normals = (trial / 4) % 2 == 0;
        const bool standard = trial < 8 || trial % 5 == 0;
        std::vector<Prop> props;
        for (const auto& name : standard_names(degree, normals)) props.push_back({name, PlyType::Float32});
        std::uniform_int_distribution<int> pick(0, 9);
        if (trial >= 8) {
            if (pick(rng) < 5) props.push_back({"confidence", PlyType::Float32});
            for (int e = pick(rng) % 3; e > 0; --e) props.push_back({"extra_" + std::to_string(e), PlyType::Float32});
            if (!standard) {
                std::shuffle(props.begin(), props.end(), rng);
                // Some columns of another type (then the whole file takes the generic path).
                for (auto& p : props)
                    if (pick(rng) == 0) p.type = p.name == "opacity" || p.name.rfind("scale_", 0) == 0
                                                     ? PlyType::Float64
                                                     : others[pick(rng) % 7];
            } else if (pick(rng) < 3) {
                // The standard prefix, then a double extra: the prefix's kernel cannot be used.
                props.push_back({"extra_double", PlyType::Float64});
            }
        }
        const bool big_endian = trial >= 8 && pick(rng) < 3;
        const std::size_t sizes[] = {1, 3, 600, 20000};  // 20000 rows: over 4 MiB, read on every thread
        const std::size_t n = sizes[trial % 4 == 3 ? 3 : pick(rng) % 3];
        const std::string path = tmp("layout.ply");
        write_file(path, ply_file(props, n, big_endian, rng));

        INFO("trial " << trial << ": degree " << degree << ", normals " << normals << ", standard " << standard
                      << ", big endian " << big_endian << ", " << n << " rows");
        const GaussianCloud ref = from_columns(path);
        omp_set_num_threads(1);
        const GaussianCloud one = avsplat::read_ply(path);
        omp_set_num_threads(std::max(2, threads));
        const GaussianCloud many = avsplat::read_ply(path);
        omp_set_num_threads(threads);
        check_same(one, ref);
        check_same(many, ref);
    }
}

TEST_CASE("read_ply: a truncated file gives the same IOError on the fast path and the generic one", "[ply]") {
    std::mt19937 rng(7);
    std::vector<Prop> standard, shuffled;
    for (const auto& name : standard_names(3, true)) standard.push_back({name, PlyType::Float32});
    shuffled = standard;
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    std::vector<std::string> messages;
    for (const auto* props : {&standard, &shuffled}) {
        const std::string bytes = ply_file(*props, 20000, false, rng);
        const std::string path = tmp("cut.ply");
        write_file(path, bytes.substr(0, bytes.size() - 1000));
        try {
            avsplat::read_ply(path);
            FAIL("no IOError");
        } catch (const IOError& e) {
            messages.push_back(e.what());
        }
    }
    CHECK_THAT(messages[0], Catch::Contains("ply_fast_cut.ply") && Catch::Contains("truncated"));
    CHECK(messages[0] == messages[1]);
}
