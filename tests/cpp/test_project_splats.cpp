// Tests of the CPU renderer's projection stage (lib/src/render/cpu/project_splats.h): under every
// kernel this build and CPU have (portable, AVX2, AVX-512), project_splats gives for every
// Gaussian the record, power_cut and sort key of the scalar reference, preprocess::project_record
// (the function the CUDA renderer calls) followed by power_cutoff and depth_index_key, bit for bit,
// culling decisions included. The clouds mix in every block ordinary Gaussians with stiff ones:
// scales 1e-8 and 1e4, means behind, at and just in front of the near plane, beyond the far plane
// and around the image border, huge splats, opacities 0, 1 and at the threshold, extreme (but
// finite, non-zero) quaternions, SH coefficients whose colour overflows to infinity; SH degrees 0 to 3,
// antialiased or not, alpha thresholds that take power_cutoff's every branch.
#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"
#include "render/cpu/blend_tile_avx2.h"
#include "render/cpu/blend_tile_avx512.h"
#include "render/cpu/project_splats.h"
#include "render/shared/view_params.h"

#include <Eigen/Geometry>
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

using avsplat::Camera;
using avsplat::GaussianCloud;
using avsplat::RenderOptions;
namespace cpu = avsplat::detail::cpu;
namespace preprocess = avsplat::preprocess;
namespace tiling = avsplat::tiling;

namespace {

/// The kernels to hold to the reference: the portable one and the vector ones this CPU runs.
std::vector<std::pair<cpu::CpuKernel, const char*>> kernels() {
    std::vector<std::pair<cpu::CpuKernel, const char*>> k{{cpu::CpuKernel::Portable, "portable"}};
    if (cpu::avx2_kernel_available()) k.emplace_back(cpu::CpuKernel::Avx2, "avx2");
    if (cpu::avx512_kernel_available()) k.emplace_back(cpu::CpuKernel::Avx512, "avx512");
    return k;
}

/// A camera at the origin looking down +z (world = camera axes up to a small rotation when
/// `tilted`), so that depths and the image border can be placed exactly; near = 0.5, far = 50.
Camera axis_camera(bool tilted, int w, int h) {
    Eigen::Matrix4d w2c = Eigen::Matrix4d::Identity();
    if (tilted) {
        w2c.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, 1.0, -0.4).normalized()).toRotationMatrix();
        w2c(0, 3) = 0.1;
        w2c(1, 3) = -0.2;
        w2c(2, 3) = 0.05;
    }
    return Camera(0.9 * w, 0.9 * w, 0.5 * w + 0.25, 0.5 * h - 0.5, w, h, w2c, 0.5, 50.0);
}

float pick(std::mt19937& rng, std::initializer_list<float> values) {
    std::uniform_int_distribution<std::size_t> d(0, values.size() - 1);
    return values.begin()[d(rng)];
}

/// n Gaussians of SH degree `degree` for axis_camera(..., w, h), each of one of several kinds
/// drawn at random (so that a block of 8 mixes kept and culled lanes of every kind).
GaussianCloud stiff_cloud(std::size_t n, int degree, std::uint32_t seed, int w, int h) {
    GaussianCloud c(n, degree);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::normal_distribution<float> g(0.0f, 1.0f);
    const int k3 = 3 * c.sh_coeffs();
    const float fx = 0.9f * float(w);
    for (std::size_t i = 0; i < n; ++i) {
        float* m = &c.means[3 * i];
        float* s = &c.scales[3 * i];
        float* q = &c.rotations[4 * i];
        // Position: in the frustum at depth 1-10, or a stiff depth, or around the image border.
        float z = 1.0f + 9.0f * u(rng);
        float px = float(w) * u(rng), py = float(h) * u(rng);  // target pixel
        const int where = int(u(rng) * 10.0f);
        if (where == 0) z = pick(rng, {0.5f, std::nextafter(0.5f, 0.0f), std::nextafter(0.5f, 1.0f), 0.0f, -1.0f,
                                       -0.5f, 50.0f, std::nextafter(50.0f, 100.0f), 1e6f});
        if (where == 1) px = pick(rng, {-0.5f, 0.0f, 0.5f, -3.0f, -40.0f, float(w), float(w) + 0.5f, float(w) + 3.0f}) +
                             0.01f * g(rng);
        if (where == 2) py = pick(rng, {-0.5f, 0.0f, 0.49f, -2.0f, float(h), float(h) - 0.5f, float(h) + 2.0f});
        if (where == 3) px = float(w) * (4.0f * u(rng) - 1.5f);  // beyond the Jacobian's clamp
        m[0] = (px - 0.5f * float(w)) * z / fx;
        m[1] = (py - 0.5f * float(h)) * z / fx;
        m[2] = z;
        // Scales: log-uniform from 1e-3 to 0.3, or stiff.
        for (int j = 0; j < 3; ++j) s[j] = std::exp(std::log(1e-3f) + u(rng) * std::log(300.0f));
        const int shape = int(u(rng) * 8.0f);
        if (shape == 0) s[int(u(rng) * 2.99f)] = 1e-8f;                        // flat
        if (shape == 1) {                                                        // needle 1e4 x 1e-8 x 1
            s[0] = 1e4f;
            s[1] = 1e-8f;
            s[2] = 1.0f;
        }
        if (shape == 2) s[0] = s[1] = s[2] = pick(rng, {1e4f, 1e3f, 30.0f});      // huge
        if (shape == 3) s[0] = s[1] = s[2] = 1e-8f;                             // point
        // Rotation: Gaussian, or extreme but finite and non-zero.
        for (int j = 0; j < 4; ++j) q[j] = g(rng);
        const int rot = int(u(rng) * 8.0f);
        if (rot == 0) q[0] = 3e38f;
        if (rot == 1) q[int(u(rng) * 3.99f)] *= 1e-38f;
        if (rot == 2) {
            q[0] = 1e-45f;  // the smallest subnormal, with zeros: still a unit quaternion
            q[1] = q[2] = q[3] = 0.0f;
        }
        if (rot == 3) {
            q[0] = -3e38f;
            q[1] = 3e38f;
            q[2] = 1.0f;
            q[3] = -1e-30f;
        }
        // Opacity: uniform, or 0, 1, or about the threshold 1/255.
        c.opacities[i] = u(rng);
        const int op = int(u(rng) * 6.0f);
        if (op == 0) c.opacities[i] = pick(rng, {0.0f, 1.0f, 1.0f / 255.0f, std::nextafter(1.0f / 255.0f, 0.0f),
                                                 std::nextafter(1.0f / 255.0f, 1.0f), 1e-30f});
        // SH: as a trained scene, or coefficients of +-3e38 whose colour may overflow to infinity.
        for (int j = 0; j < k3; ++j) c.sh[i * std::size_t(k3) + std::size_t(j)] = (j < 3 ? 1.0f : 0.3f) * g(rng);
        if (u(rng) < 0.05f)
            for (int j = 0; j < k3; ++j) c.sh[i * std::size_t(k3) + std::size_t(j)] = pick(rng, {3e38f, -3e38f, 1.0f});
    }
    return c;
}

std::uint32_t bits(float x) {
    std::uint32_t b;
    std::memcpy(&b, &x, sizeof b);
    return b;
}

/// The first field where two records differ, or "" when all 15 fields are the same bits.
std::string first_difference(const cpu::SplatRecord<float>& a, const cpu::SplatRecord<float>& b) {
    const char* names[] = {"mean_x", "mean_y", "conic_a", "conic_b", "conic_c", "opacity", "rgb[0]", "rgb[1]",
                           "rgb[2]", "depth"};
    const float fa[] = {a.mean_x, a.mean_y, a.conic_a, a.conic_b, a.conic_c, a.opacity, a.rgb[0], a.rgb[1], a.rgb[2], a.depth};
    const float fb[] = {b.mean_x, b.mean_y, b.conic_a, b.conic_b, b.conic_c, b.opacity, b.rgb[0], b.rgb[1], b.rgb[2], b.depth};
    for (int k = 0; k < 10; ++k)
        if (bits(fa[k]) != bits(fb[k]))
            return std::string(names[k]) + " " + std::to_string(fa[k]) + " vs " + std::to_string(fb[k]);
    if (a.x_min != b.x_min || a.x_max != b.x_max || a.y_min != b.y_min || a.y_max != b.y_max) return "pixel box";
    if (bits(a.power_cut) != bits(b.power_cut))
        return "power_cut " + std::to_string(a.power_cut) + " vs " + std::to_string(b.power_cut);
    return "";
}

/// What the reference gave, to show that a case exercised the paths it is meant to.
struct Coverage {
    std::size_t kept = 0, culled = 0, border = 0, cut_neg_inf = 0;
};

/// Holds project_splats over [begin, end) under every kernel to the reference; returns what the
/// reference saw.
Coverage check_range(const GaussianCloud& c, const Camera& cam, const RenderOptions& o, std::int64_t begin,
                     std::int64_t end) {
    const preprocess::ViewParams<float> view = preprocess::view_params<float>(cam, o, c.sh_degree);
    const std::size_t n = c.size();
    // The reference: project_record, power_cutoff, depth_index_key, one Gaussian at a time.
    std::vector<cpu::SplatRecord<float>> ref(n);
    std::vector<std::uint64_t> ref_keys(n, 0);
    Coverage cov;
    for (std::int64_t i = begin; i < end; ++i) {
        const std::size_t k = std::size_t(i);
        const std::uint32_t tiles = preprocess::project_record(
            view, &c.means[3 * k], &c.scales[3 * k], &c.rotations[4 * k], c.opacities[k],
            &c.sh[k * std::size_t(3 * c.sh_coeffs())], ref[k]);
        if (tiles == 0) {
            ref_keys[k] = cpu::kCulledKey;
            ++cov.culled;
            continue;
        }
        ref[k].power_cut = cpu::power_cutoff(ref[k], o.alpha_threshold);
        ref_keys[k] = tiling::depth_index_key(ref[k].depth, std::uint32_t(i));
        ++cov.kept;
        cov.border += ref[k].x_min == 0 || ref[k].y_min == 0 || ref[k].x_max == cam.width - 1 ||
                      ref[k].y_max == cam.height - 1;
        cov.cut_neg_inf += ref[k].power_cut == -std::numeric_limits<float>::infinity();
    }
    for (const auto& [kernel, name] : kernels()) {
        INFO("kernel " << name);
        std::unique_ptr<cpu::SplatRecord<float>[]> got(new cpu::SplatRecord<float>[n]);
        std::memset(static_cast<void*>(got.get()), 0x5a, n * sizeof(cpu::SplatRecord<float>));
        std::vector<std::uint64_t> keys(n, 12345);
        cpu::project_splats(kernel, view, c, o.alpha_threshold, begin, end, got.get(), keys.data());
        std::size_t bad = 0;
        for (std::int64_t i = begin; i < end && bad < 5; ++i) {
            const std::size_t k = std::size_t(i);
            INFO("Gaussian " << i << ": mean " << c.means[3 * k] << " " << c.means[3 * k + 1] << " "
                             << c.means[3 * k + 2] << ", scale " << c.scales[3 * k] << " " << c.scales[3 * k + 1]
                             << " " << c.scales[3 * k + 2] << ", opacity " << c.opacities[k]);
            if (keys[k] != ref_keys[k]) {
                ++bad;
                CHECK(keys[k] == ref_keys[k]);
                continue;
            }
            if (ref_keys[k] == cpu::kCulledKey) continue;
            const std::string diff = first_difference(got[k], ref[k]);
            if (!diff.empty()) ++bad;
            CHECK(diff == "");
        }
        CHECK(bad == 0);
        // Nothing outside the range is written.
        for (std::size_t k = 0; k < n; ++k)
            if (std::int64_t(k) < begin || std::int64_t(k) >= end) REQUIRE(keys[k] == 12345);
    }
    return cov;
}

}  // namespace

TEST_CASE("project_splats: every kernel gives project_record's records, cuts and keys bit for bit", "[render][project]") {
    const int w = 203, h = 117;  // not multiples of the tile size
    Coverage total;
    for (int degree = 0; degree <= 3; ++degree) {
        for (int variant = 0; variant < 4; ++variant) {
            INFO("SH degree " << degree << ", variant " << variant);
            const GaussianCloud c = stiff_cloud(1003, degree, 17u + 7u * std::uint32_t(degree) + 101u * std::uint32_t(variant), w, h);
            const Camera cam = axis_camera(variant % 2 == 1, w, h);
            RenderOptions o;
            o.antialiased = variant >= 2;
            if (variant == 3) o.extent_sigma = 2.5f;
            const Coverage cov = check_range(c, cam, o, 0, std::int64_t(c.size()));
            total.kept += cov.kept;
            total.culled += cov.culled;
            total.border += cov.border;
            total.cut_neg_inf += cov.cut_neg_inf;
            // A range that starts and ends inside blocks of 8.
            check_range(c, cam, o, 5, std::int64_t(c.size()) - 3);
        }
    }
    // The clouds reach the paths the test is about (else it could not fail where they differ).
    CHECK(total.kept > 4000);
    CHECK(total.culled > 2000);
    CHECK(total.border > 100);
    CHECK(total.cut_neg_inf > 0);  // a colour that overflowed to infinity
}

TEST_CASE("project_splats: power_cutoff's branches on lanes (threshold 0, subnormal quotients)", "[render][project]") {
    const int w = 96, h = 64;
    const GaussianCloud c = stiff_cloud(517, 3, 99u, w, h);
    const Camera cam = axis_camera(true, w, h);
    for (const float threshold : {0.0f, 1e-39f, 1e-45f, 1e-37f, 0.5f, 1.0f}) {
        INFO("alpha_threshold " << threshold);
        RenderOptions o;
        o.alpha_threshold = threshold;
        const Coverage cov = check_range(c, cam, o, 0, std::int64_t(c.size()));
        CHECK(cov.kept > 0);
        if (threshold == 0.0f) CHECK(cov.cut_neg_inf == cov.kept);  // alpha_threshold > 0 fails
    }
}

TEST_CASE("project_splats: the float records are one 64-byte line in the order the kernels store", "[render][project]") {
    cpu::SplatRecord<float> r;
    const char* base = reinterpret_cast<const char*>(&r);
    CHECK(sizeof r == 64);
    CHECK(reinterpret_cast<const char*>(&r.mean_x) - base == 0);
    CHECK(reinterpret_cast<const char*>(&r.opacity) - base == 20);
    CHECK(reinterpret_cast<const char*>(&r.rgb[0]) - base == 24);
    CHECK(reinterpret_cast<const char*>(&r.depth) - base == 36);
    CHECK(reinterpret_cast<const char*>(&r.x_min) - base == 40);
    CHECK(reinterpret_cast<const char*>(&r.y_max) - base == 52);
    CHECK(reinterpret_cast<const char*>(&r.power_cut) - base == 56);
}
