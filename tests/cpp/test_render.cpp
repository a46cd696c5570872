// Tests of the CPU splat renderer and of the shared header-only maths (projection.h, blend.h,
// tiling.h, sh.h).
//
// References written here, independently of lib/src/render_cpu.cpp:
//   - closed-form images of one isotropic Gaussian and of two stacked ones;
//   - the real SH basis evaluated from associated Legendre functions (std::assoc_legendre);
//   - a brute-force renderer in double with Eigen: every Gaussian against every pixel, sorted
//     by (depth, index), no tiles and no culling beyond the rules;
//   - the float64 path of the renderer itself, to bound the float32 path's error.
#include "render/shared/blend.h"
#include "avsplat/core/camera.h"
#include "avsplat/core/error.h"
#include "avsplat/core/gaussians.h"
#include "render/shared/projection.h"
#include "avsplat/render/render.h"
#include "avsplat/core/sh.h"
#include "render/shared/tiling.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <vector>

using avsplat::Camera;
using avsplat::GaussianCloud;
using avsplat::Precision;
using avsplat::RenderOptions;
using avsplat::RenderResult;
using Catch::Matchers::Contains;

namespace {

constexpr double kC0 = 0.28209479177387814;

// ---------------------------------------------------------------------------------------------
// Scene helpers

/// A camera at the origin looking down +z (identity world_to_camera).
Camera axis_camera(int w, int h, double f, double cx, double cy) {
    return Camera(f, f, cx, cy, w, h);
}

/// Appends one Gaussian (degree of `c`) with the given values; SH coefficients beyond dc are 0.
void add_gaussian(GaussianCloud& c, const Eigen::Vector3d& mean, const Eigen::Vector3d& scale,
                  const Eigen::Vector4d& quat, double opacity, const Eigen::Vector3d& rgb) {
    const int k = c.sh_coeffs();
    for (int j = 0; j < 3; ++j) c.means.push_back(float(mean[j]));
    for (int j = 0; j < 3; ++j) c.scales.push_back(float(scale[j]));
    for (int j = 0; j < 4; ++j) c.rotations.push_back(float(quat[j]));
    c.opacities.push_back(float(opacity));
    for (int j = 0; j < k * 3; ++j) c.sh.push_back(j < 3 ? float((rgb[j] - 0.5) / kC0) : 0.0f);
}

Eigen::Vector4d identity_quat() { return Eigen::Vector4d(1, 0, 0, 0); }

/// Random scene: n Gaussians with means in a box in front of an axis camera, random
/// rotations, log-uniform scales, opacities in [0, max_opacity], SH of `degree`.
GaussianCloud random_scene(std::size_t n, int degree, double max_opacity, std::uint32_t seed,
                           double scale_lo = 0.02, double scale_hi = 0.3) {
    GaussianCloud c(0, degree);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0), zd(1.5, 6.0),
        ls(std::log(scale_lo), std::log(scale_hi)), op(0.0, max_opacity);
    std::normal_distribution<double> g(0.0, 1.0);
    for (std::size_t i = 0; i < n; ++i) {
        const double z = zd(rng);
        Eigen::Vector3d mean(1.6 * u(rng) * z * 0.6, 1.2 * u(rng) * z * 0.6, z);
        Eigen::Vector3d scale(std::exp(ls(rng)), std::exp(ls(rng)), std::exp(ls(rng)));
        Eigen::Vector4d q(g(rng), g(rng), g(rng), g(rng));
        add_gaussian(c, mean, scale, q, op(rng), Eigen::Vector3d(0.5, 0.5, 0.5));
        const int k = c.sh_coeffs();
        for (int j = 0; j < k * 3; ++j) c.sh[i * k * 3 + j] = float((j < 3 ? 1.0 : 0.3) * g(rng));
    }
    return c;
}

bool all_finite(const std::vector<float>& v) {
    return std::all_of(v.begin(), v.end(), [](float x) { return std::isfinite(x); });
}

// ---------------------------------------------------------------------------------------------
// Independent references

double factorial(int n) { return n <= 1 ? 1.0 : n * factorial(n - 1); }

/// Real spherical harmonic Y_l^m with the Condon-Shortley phase at the unit direction d, from
/// associated Legendre functions (libstdc++'s std::assoc_legendre omits the (-1)^m phase).
double real_sh(int l, int m, const Eigen::Vector3d& d) {
    const double theta = std::acos(std::clamp(d.z(), -1.0, 1.0)), phi = std::atan2(d.y(), d.x());
    const int am = std::abs(m);
    const double K = std::sqrt((2.0 * l + 1.0) / (4.0 * M_PI) * factorial(l - am) / factorial(l + am));
    const double P = std::assoc_legendre(unsigned(l), unsigned(am), std::cos(theta)) * (am % 2 ? -1.0 : 1.0);
    if (m == 0) return K * P;
    if (m > 0) return std::sqrt(2.0) * K * std::cos(m * phi) * P;
    return std::sqrt(2.0) * K * std::sin(am * phi) * P;
}

/// The colour 3DGS gives Gaussian i seen from `eye`: SH + 0.5, clamped at 0.
Eigen::Vector3d reference_color(const GaussianCloud& c, std::size_t i, const Eigen::Vector3d& eye) {
    const Eigen::Vector3d d = (c.mean(i).cast<double>() - eye).normalized();
    const int k = c.sh_coeffs();
    Eigen::Vector3d rgb = Eigen::Vector3d::Zero();
    for (int l = 0; l <= c.sh_degree; ++l)
        for (int m = -l; m <= l; ++m) {
            const double y = real_sh(l, m, d);
            for (int ch = 0; ch < 3; ++ch) rgb[ch] += y * c.sh[(i * k + std::size_t(l * l + l + m)) * 3 + ch];
        }
    for (int ch = 0; ch < 3; ++ch) rgb[ch] = std::max(rgb[ch] + 0.5, 0.0);
    return rgb;
}

struct RefSplat {
    Eigen::Vector2d mean;
    Eigen::Matrix2d conic;
    Eigen::Matrix2d cov;
    double opacity;
    Eigen::Vector3d rgb;
    double depth;
    double radius_x, radius_y;
    std::uint32_t index;
};

/// Projection by the rules of projection.h, written with Eigen in double.
bool reference_project(const GaussianCloud& c, std::size_t i, const Camera& cam, const RenderOptions& o,
                       RefSplat& s) {
    const Eigen::Matrix3d R = cam.world_to_camera.topLeftCorner<3, 3>();
    const Eigen::Vector3d t = cam.world_to_camera.topRightCorner<3, 1>();
    const Eigen::Vector3d mc = R * c.mean(i).cast<double>() + t;
    if (mc.z() < cam.near || mc.z() > cam.far) return false;
    const Eigen::Matrix3d Sc = R * c.covariance(i) * R.transpose();
    const double tan_x = 0.5 * cam.width / cam.fx, tan_y = 0.5 * cam.height / cam.fy;
    const double u = std::clamp(mc.x() / mc.z(), -(cam.cx / cam.fx + 0.3 * tan_x),
                                (cam.width - cam.cx) / cam.fx + 0.3 * tan_x);
    const double v = std::clamp(mc.y() / mc.z(), -(cam.cy / cam.fy + 0.3 * tan_y),
                                (cam.height - cam.cy) / cam.fy + 0.3 * tan_y);
    Eigen::Matrix<double, 2, 3> J;
    J << cam.fx / mc.z(), 0, -cam.fx * u / mc.z(), 0, cam.fy / mc.z(), -cam.fy * v / mc.z();
    Eigen::Matrix2d cov = J * Sc * J.transpose();
    const double det0 = cov.determinant();
    cov += o.low_pass * Eigen::Matrix2d::Identity();
    const double det1 = cov.determinant();
    if (!(det1 > 0)) return false;
    s.cov = cov;
    s.conic = cov.inverse();
    s.opacity = c.opacities[i] * (o.antialiased ? std::sqrt(std::max(0.0, det0 / det1)) : 1.0);
    s.mean = Eigen::Vector2d(cam.fx * mc.x() / mc.z() + cam.cx, cam.fy * mc.y() / mc.z() + cam.cy);
    s.rgb = reference_color(c, i, cam.position());
    s.depth = mc.z();
    s.radius_x = o.extent_sigma * std::sqrt(cov(0, 0));
    s.radius_y = o.extent_sigma * std::sqrt(cov(1, 1));
    s.index = std::uint32_t(i);
    return true;
}

struct RefImage {
    int width = 0, height = 0;
    std::vector<double> color, alpha, depth;
    std::vector<int> contributors;
};

/// Brute force: every Gaussian against every pixel, front to back by (float depth, index).
/// With use_box, a Gaussian only touches pixel centres inside its k-sigma box (the renderer's
/// radius rule); without, it touches every pixel.
RefImage reference_render(const GaussianCloud& c, const Camera& cam, const RenderOptions& o, bool use_box) {
    std::vector<RefSplat> splats;
    for (std::size_t i = 0; i < c.size(); ++i) {
        RefSplat s;
        if (reference_project(c, i, cam, o, s)) splats.push_back(s);
    }
    std::sort(splats.begin(), splats.end(), [](const RefSplat& a, const RefSplat& b) {
        const float da = float(a.depth), db = float(b.depth);
        return da != db ? da < db : a.index < b.index;
    });
    RefImage img;
    img.width = cam.width;
    img.height = cam.height;
    const std::size_t np = std::size_t(cam.width) * cam.height;
    img.color.assign(3 * np, 0.0);
    img.alpha.assign(np, 0.0);
    img.depth.assign(np, 0.0);
    img.contributors.assign(np, 0);
    for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
            const Eigen::Vector2d p(x + 0.5, y + 0.5);
            double T = 1.0, dsum = 0.0;
            Eigen::Vector3d csum = Eigen::Vector3d::Zero();
            int count = 0;
            for (const RefSplat& s : splats) {
                const Eigen::Vector2d d = p - s.mean;
                if (use_box && (std::abs(d.x()) > s.radius_x || std::abs(d.y()) > s.radius_y)) continue;
                const double power = -0.5 * d.dot(s.conic * d);
                if (power > 0) continue;
                const double alpha = std::min(0.99, s.opacity * std::exp(power));
                if (alpha < o.alpha_threshold) continue;
                if (T * (1 - alpha) < o.transmittance_stop) break;
                csum += alpha * T * s.rgb;
                dsum += alpha * T * s.depth;
                T *= 1 - alpha;
                ++count;
            }
            const std::size_t k = std::size_t(y) * cam.width + x;
            for (int ch = 0; ch < 3; ++ch) img.color[3 * k + ch] = csum[ch] + T * o.background[ch];
            img.alpha[k] = 1 - T;
            img.depth[k] = T < 1 ? dsum / (1 - T) : 0.0;
            img.contributors[k] = count;
        }
    return img;
}

struct Diff {
    double max_color = 0, mean_color = 0, max_alpha = 0, max_depth_rel = 0;
    long contributor_mismatches = 0;
};

Diff compare(const RenderResult& r, const RefImage& ref) {
    Diff d;
    const std::size_t np = ref.alpha.size();
    REQUIRE(r.color.size() == 3 * np);
    for (std::size_t k = 0; k < np; ++k) {
        for (int ch = 0; ch < 3; ++ch) {
            const double e = std::abs(r.color[3 * k + ch] - ref.color[3 * k + ch]);
            d.max_color = std::max(d.max_color, e);
            d.mean_color += e / double(3 * np);
        }
        d.max_alpha = std::max(d.max_alpha, std::abs(r.alpha[k] - ref.alpha[k]));
        if (ref.depth[k] > 0)
            d.max_depth_rel = std::max(d.max_depth_rel, std::abs(r.depth[k] - ref.depth[k]) / ref.depth[k]);
        else if (r.depth[k] != 0.0f)
            d.max_depth_rel = std::numeric_limits<double>::infinity();
        d.contributor_mismatches += r.contributors[k] != ref.contributors[k];
    }
    return d;
}

RenderOptions with_precision(Precision p) {
    RenderOptions o;
    o.precision = p;
    return o;
}

}  // namespace

// =============================================================================================
// Shared maths

TEST_CASE("covariance_3d matches R S S^T R^T of GaussianCloud::covariance", "[render][projection]") {
    const GaussianCloud c = random_scene(50, 0, 1.0, 11);
    for (std::size_t i = 0; i < c.size(); ++i) {
        double cov[6];
        avsplat::projection::covariance_3d(&c.rotations[4 * i], &c.scales[3 * i], cov);
        const Eigen::Matrix3d ref = c.covariance(i);
        const double tol = 1e-12 * ref.norm();
        CHECK(std::abs(cov[0] - ref(0, 0)) <= tol);
        CHECK(std::abs(cov[1] - ref(0, 1)) <= tol);
        CHECK(std::abs(cov[2] - ref(0, 2)) <= tol);
        CHECK(std::abs(cov[3] - ref(1, 1)) <= tol);
        CHECK(std::abs(cov[4] - ref(1, 2)) <= tol);
        CHECK(std::abs(cov[5] - ref(2, 2)) <= tol);
    }
}

TEST_CASE("project_mean_covariance is J W Sigma W^T J^T with the clamped Jacobian", "[render][projection]") {
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> u(-1, 1);
    const avsplat::projection::Intrinsics<double> K{500.0, 450.0, 320.0, 200.0, 640, 400};
    for (int trial = 0; trial < 100; ++trial) {
        // Means well inside and far outside the field of view (the clamp must act on these).
        const double z = 1.0 + 3.0 * (u(rng) + 1.0);
        const double spread = trial % 2 ? 0.5 : 4.0;
        const double mc[3] = {spread * u(rng) * z, spread * u(rng) * z, z};
        Eigen::Matrix3d A = Eigen::Matrix3d::Random();
        const Eigen::Matrix3d S = A * A.transpose() + 0.1 * Eigen::Matrix3d::Identity();
        const double cov_c[6] = {S(0, 0), S(0, 1), S(0, 2), S(1, 1), S(1, 2), S(2, 2)};
        double mean2d[2], cov2d[3];
        avsplat::projection::project_mean_covariance(mc, cov_c, K, mean2d, cov2d);
        const double lim_x = 0.3 * 0.5 * K.width / K.fx, lim_y = 0.3 * 0.5 * K.height / K.fy;
        const double cu = std::clamp(mc[0] / z, -K.cx / K.fx - lim_x, (K.width - K.cx) / K.fx + lim_x);
        const double cv = std::clamp(mc[1] / z, -K.cy / K.fy - lim_y, (K.height - K.cy) / K.fy + lim_y);
        Eigen::Matrix<double, 2, 3> J;
        J << K.fx / z, 0, -K.fx * cu / z, 0, K.fy / z, -K.fy * cv / z;
        const Eigen::Matrix2d ref = J * S * J.transpose();
        CHECK(mean2d[0] == Approx(K.fx * mc[0] / z + K.cx).epsilon(1e-12));
        CHECK(mean2d[1] == Approx(K.fy * mc[1] / z + K.cy).epsilon(1e-12));
        CHECK(cov2d[0] == Approx(ref(0, 0)).epsilon(1e-10));
        CHECK(cov2d[1] == Approx(ref(0, 1)).epsilon(1e-10).margin(1e-10 * ref.norm()));
        CHECK(cov2d[2] == Approx(ref(1, 1)).epsilon(1e-10));
    }
}

TEST_CASE("radius rule: the box is the bounding box of the k-sigma ellipse", "[render][projection]") {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int trial = 0; trial < 200; ++trial) {
        Eigen::Matrix2d A = Eigen::Matrix2d::Random() * (1.0 + 20.0 * std::abs(u(rng)));
        const Eigen::Matrix2d C = A * A.transpose() + 0.3 * Eigen::Matrix2d::Identity();
        const double cov2d[3] = {C(0, 0), C(0, 1), C(1, 1)};
        const double k = 3.0;
        double radius[2];
        avsplat::projection::splat_radius(cov2d, k, radius);
        // Points of the ellipse d^T C^-1 d = k^2 are d = k L (cos a, sin a) with C = L L^T.
        const Eigen::Matrix2d L = C.llt().matrixL();
        double max_x = 0, max_y = 0;
        for (int s = 0; s < 3600; ++s) {
            const double a = 2 * M_PI * s / 3600;
            const Eigen::Vector2d d = k * L * Eigen::Vector2d(std::cos(a), std::sin(a));
            REQUIRE(std::abs(d.x()) <= radius[0] * (1 + 1e-12));
            REQUIRE(std::abs(d.y()) <= radius[1] * (1 + 1e-12));
            max_x = std::max(max_x, std::abs(d.x()));
            max_y = std::max(max_y, std::abs(d.y()));
        }
        // Tight: the ellipse reaches the box (up to the angular sampling).
        CHECK(max_x >= radius[0] * (1 - 1e-5));
        CHECK(max_y >= radius[1] * (1 - 1e-5));
    }
}

TEST_CASE("pixel_span lists exactly the pixel centres inside [c - r, c + r], clipped", "[render][projection]") {
    std::mt19937 rng(9);
    std::uniform_real_distribution<double> c(-20, 60), r(0, 15);
    for (int trial = 0; trial < 2000; ++trial) {
        const double center = c(rng), radius = r(rng);
        int lo = -1, hi = -1;
        const bool any = avsplat::projection::pixel_span(center, radius, 40, lo, hi);
        int first = -1, last = -1;
        for (int i = 0; i < 40; ++i)
            if (std::abs(i + 0.5 - center) <= radius) {
                if (first < 0) first = i;
                last = i;
            }
        REQUIRE(any == (first >= 0));
        if (any) {
            CHECK(lo == first);
            CHECK(hi == last);
        }
    }
    int lo = 0, hi = 0;
    CHECK_FALSE(avsplat::projection::pixel_span(std::numeric_limits<double>::quiet_NaN(), 1.0, 10, lo, hi));
    CHECK(avsplat::projection::pixel_span(5.0, 1e30, 10, lo, hi));
    CHECK((lo == 0 && hi == 9));
    CHECK_FALSE(avsplat::projection::pixel_span(-1e30f, 1e3f, 10, lo, hi));
}

TEST_CASE("float exp_nonpositive agrees with std::exp to float accuracy", "[render][blend]") {
    double worst = 0;
    for (int i = 0; i <= 200000; ++i) {
        const float x = -87.0f * float(i) / 200000.0f;
        const double ref = std::exp(double(x));
        worst = std::max(worst, std::abs(avsplat::blend::exp_nonpositive(x) - ref) / ref);
    }
    CHECK(worst < 3e-7);
    CHECK(avsplat::blend::exp_nonpositive(0.0f) == 1.0f);
    CHECK(avsplat::blend::exp_nonpositive(2.0f) == 1.0f);  // x > 0 is treated as 0
    CHECK(avsplat::blend::exp_nonpositive(-100.0f) == 0.0f);
    CHECK(avsplat::blend::exp_nonpositive(std::numeric_limits<float>::quiet_NaN()) == 0.0f);
    CHECK(avsplat::blend::exp_nonpositive(-1.5) == std::exp(-1.5));
}

TEST_CASE("blend_step applies the 3DGS rules", "[render][blend]") {
    using avsplat::blend::blend_step;
    const double thr = 1.0 / 255.0, stop = 1e-4;
    auto s = blend_step(0.5, 1.0, thr, stop);
    CHECK(s.blended == 1);
    CHECK(s.saturated == 0);
    CHECK(s.weight == 0.5);
    CHECK(s.next_transmittance == 0.5);
    s = blend_step(0.003, 0.5, thr, stop);  // below 1/255: skipped
    CHECK(s.blended == 0);
    CHECK(s.saturated == 0);
    CHECK(s.weight == 0.0);
    CHECK(s.next_transmittance == 0.5);
    s = blend_step(0.99, 0.005, thr, stop);  // 0.005 * 0.01 < 1e-4: saturates, not blended
    CHECK(s.blended == 0);
    CHECK(s.saturated == 1);
    CHECK(s.weight == 0.0);
    CHECK(s.next_transmittance == 0.005);
    CHECK(avsplat::blend::splat_alpha(1.0, 0.0) == 0.99);
    CHECK(avsplat::blend::splat_alpha(0.5, 1e-3) == 0.0);  // positive power: skipped
    CHECK(avsplat::blend::splat_alpha(0.5, -1.0) == Approx(0.5 * std::exp(-1.0)));
}

TEST_CASE("tiling: tile rectangles and sort keys", "[render][tiling]") {
    using namespace avsplat::tiling;
    CHECK(tiles_along(1) == 1);
    CHECK(tiles_along(16) == 1);
    CHECK(tiles_along(17) == 2);
    CHECK(tiles_along(1280) == 80);
    // Pixel box [15, 16] x [0, 47] touches tile columns 0 and 1 and tile rows 0..2.
    const TileRect r = tile_rect(15, 16, 0, 47);
    CHECK((r.x0 == 0 && r.x1 == 2 && r.y0 == 0 && r.y1 == 3));
    CHECK(tile_count(r) == 6);
    CHECK(tile_count(tile_rect(3, 3, 20, 20)) == 1);
    // Every tile of the rectangle contains a pixel of the box, and no other tile does.
    std::mt19937 rng(1);
    std::uniform_int_distribution<int> px(0, 200);
    for (int trial = 0; trial < 500; ++trial) {
        int x0 = px(rng), x1 = px(rng), y0 = px(rng), y1 = px(rng);
        if (x0 > x1) std::swap(x0, x1);
        if (y0 > y1) std::swap(y0, y1);
        const TileRect t = tile_rect(x0, x1, y0, y1);
        for (int ty = 0; ty < 14; ++ty)
            for (int tx = 0; tx < 14; ++tx) {
                const bool meets = tx * 16 <= x1 && tx * 16 + 15 >= x0 && ty * 16 <= y1 && ty * 16 + 15 >= y0;
                const bool listed = tx >= t.x0 && tx < t.x1 && ty >= t.y0 && ty < t.y1;
                REQUIRE(meets == listed);
            }
    }
    // depth_bits orders like the floats, negative ones included.
    std::uniform_real_distribution<float> f(-1e3f, 1e3f);
    for (int trial = 0; trial < 10000; ++trial) {
        const float a = f(rng), b = trial % 3 ? f(rng) : a * 1e-30f;
        REQUIRE((a < b) == (depth_bits(a) < depth_bits(b)));
        REQUIRE((a == b) == (depth_bits(a) == depth_bits(b)));
    }
    // Global key: tile first, then depth. Per-tile key: depth first, then index.
    CHECK(tile_depth_key(1, 100.0f) < tile_depth_key(2, 0.5f));
    CHECK(tile_depth_key(2, 0.5f) < tile_depth_key(2, 0.75f));
    CHECK(depth_index_key(0.5f, 7) < depth_index_key(0.5f, 8));
    CHECK(depth_index_key(0.5f, 9) < depth_index_key(0.75f, 8));
    CHECK(key_index(depth_index_key(3.0f, 123456)) == 123456u);
}

TEST_CASE("eval_sh of degree 1..3 matches the real SH basis from Legendre functions", "[render][sh]") {
    std::mt19937 rng(2);
    std::normal_distribution<double> g(0, 1);
    for (int degree = 0; degree <= 3; ++degree) {
        const int k = (degree + 1) * (degree + 1);
        for (int trial = 0; trial < 50; ++trial) {
            std::vector<float> coeffs(std::size_t(3 * k));
            for (float& v : coeffs) v = float(g(rng));
            const Eigen::Vector3d d = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
            double rgb[3];
            avsplat::sh::eval_sh(degree, coeffs.data(), d.x(), d.y(), d.z(), rgb);
            for (int ch = 0; ch < 3; ++ch) {
                double ref = 0;
                for (int l = 0; l <= degree; ++l)
                    for (int m = -l; m <= l; ++m) ref += real_sh(l, m, d) * coeffs[std::size_t(l * l + l + m) * 3 + ch];
                REQUIRE(rgb[ch] == Approx(ref).margin(1e-12));
            }
        }
    }
}

// =============================================================================================
// Rendering: closed forms

TEST_CASE("render: one isotropic Gaussian facing the camera matches the closed form", "[render]") {
    const int W = 48, H = 40;
    const double f = 60.0, cx = 23.3, cy = 21.1;
    const Camera cam = axis_camera(W, H, f, cx, cy);
    const Eigen::Vector3d mean(0.25, -0.1, 2.0), rgb(0.8, 0.3, 0.1);
    const double s = 0.05, opacity = 0.7;
    GaussianCloud c(0, 0);
    add_gaussian(c, mean, Eigen::Vector3d(s, s, s), Eigen::Vector4d(0.3, -0.2, 0.8, 0.1), opacity, rgb);
    const bool antialiased = GENERATE(false, true);
    const Precision precision = GENERATE(Precision::Float32, Precision::Float64);
    RenderOptions o;
    o.antialiased = antialiased;
    o.precision = precision;
    o.background = {0.1f, 0.2f, 0.9f};
    const RenderResult r = avsplat::render(c, cam, o);
    REQUIRE(r.width == W);
    REQUIRE(r.height == H);
    // cov2d = s^2 (f/z)^2 [[1 + u^2, u v], [u v, 1 + v^2]] + 0.3 I, u = x/z, v = y/z.
    const double z = mean.z(), u = mean.x() / z, v = mean.y() / z, g2 = s * s * f * f / (z * z);
    Eigen::Matrix2d cov;
    cov << g2 * (1 + u * u), g2 * u * v, g2 * u * v, g2 * (1 + v * v);
    const double det0 = cov.determinant();
    cov += 0.3 * Eigen::Matrix2d::Identity();
    const double comp = antialiased ? std::sqrt(det0 / cov.determinant()) : 1.0;
    const Eigen::Matrix2d conic = cov.inverse();
    const Eigen::Vector2d m2(f * u + cx, f * v + cy);
    const double rx = 3 * std::sqrt(cov(0, 0)), ry = 3 * std::sqrt(cov(1, 1));
    const double tol = precision == Precision::Float64 ? 1e-6 : 2e-5;
    int lit = 0, ambiguous = 0;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const Eigen::Vector2d d = Eigen::Vector2d(x + 0.5, y + 0.5) - m2;
            const double a = std::min(0.99, opacity * comp * std::exp(-0.5 * d.dot(conic * d)));
            const bool inside = std::abs(d.x()) <= rx && std::abs(d.y()) <= ry;
            // Pixels within rounding of a rule's boundary may go either way.
            if (std::abs(a - 1 / 255.0) < 1e-6 || std::abs(std::abs(d.x()) - rx) < 1e-4 ||
                std::abs(std::abs(d.y()) - ry) < 1e-4) {
                ++ambiguous;
                continue;
            }
            const double alpha = inside && a >= 1 / 255.0 ? a : 0.0;
            const std::size_t k = std::size_t(y) * W + x;
            lit += alpha > 0;
            REQUIRE(r.alpha[k] == Approx(alpha).margin(tol));
            for (int ch = 0; ch < 3; ++ch)
                REQUIRE(r.color[3 * k + ch] == Approx(alpha * rgb[ch] + (1 - alpha) * o.background[ch]).margin(tol));
            // Expected depth divides by 1 - T, which float32 rounds to ~6e-8 absolute: relative
            // error up to 6e-8 / (1/255) = 1.5e-5 at the faintest pixels.
            REQUIRE(r.depth[k] == Approx(alpha > 0 ? z : 0.0).epsilon(precision == Precision::Float64 ? 1e-7 : 3e-5));
            REQUIRE(r.contributors[k] == (alpha > 0 ? 1 : 0));
        }
    CHECK(lit > 50);
    CHECK(ambiguous <= 2);
    CHECK(r.stats.visible == 1);
    CHECK(r.stats.contributions == std::uint64_t(lit));
}

TEST_CASE("render: two overlapping Gaussians composite front to back by depth, ties by index", "[render]") {
    const int W = 32, H = 32;
    const Camera cam = axis_camera(W, H, 40.0, 16.0, 16.0);
    const Eigen::Vector3d red(0.9, 0.1, 0.1), green(0.1, 0.8, 0.2);
    const double a1 = 0.6, a2 = 0.5;
    // Large Gaussians whose means project to pixel centre (15.5, 15.5): both are nearly flat
    // there, so the centre pixel's alphas are the opacities up to exp(-tiny).
    auto make = [&](double z_red, double z_green, bool red_first) {
        GaussianCloud c(0, 0);
        const Eigen::Vector3d m_red(-0.5 / 40.0 * z_red, -0.5 / 40.0 * z_red, z_red);
        const Eigen::Vector3d m_green(-0.5 / 40.0 * z_green, -0.5 / 40.0 * z_green, z_green);
        if (red_first) {
            add_gaussian(c, m_red, Eigen::Vector3d(1, 1, 1) * z_red, identity_quat(), a1, red);
            add_gaussian(c, m_green, Eigen::Vector3d(1, 1, 1) * z_green, identity_quat(), a2, green);
        } else {
            add_gaussian(c, m_green, Eigen::Vector3d(1, 1, 1) * z_green, identity_quat(), a2, green);
            add_gaussian(c, m_red, Eigen::Vector3d(1, 1, 1) * z_red, identity_quat(), a1, red);
        }
        return c;
    };
    const std::size_t centre = 15 * W + 15;
    RenderOptions o = with_precision(GENERATE(Precision::Float32, Precision::Float64));
    o.background = {0.0f, 0.0f, 1.0f};
    const Eigen::Vector3d bg(0, 0, 1);
    // Red in front (z = 2) of green (z = 3), whatever the order of the input.
    for (const bool red_first : {true, false}) {
        const RenderResult r = avsplat::render(make(2.0, 3.0, red_first), cam, o);
        const Eigen::Vector3d expect = a1 * red + (1 - a1) * a2 * green + (1 - a1) * (1 - a2) * bg;
        for (int ch = 0; ch < 3; ++ch) CHECK(r.color[3 * centre + ch] == Approx(expect[ch]).margin(1e-5));
        CHECK(r.alpha[centre] == Approx(1 - (1 - a1) * (1 - a2)).margin(1e-5));
        CHECK(r.depth[centre] == Approx((a1 * 2.0 + (1 - a1) * a2 * 3.0) / (1 - (1 - a1) * (1 - a2))).epsilon(1e-5));
        CHECK(r.contributors[centre] == 2);
    }
    // Green in front when it is nearer.
    {
        const RenderResult r = avsplat::render(make(3.0, 2.0, true), cam, o);
        const Eigen::Vector3d expect = a2 * green + (1 - a2) * a1 * red + (1 - a1) * (1 - a2) * bg;
        for (int ch = 0; ch < 3; ++ch) CHECK(r.color[3 * centre + ch] == Approx(expect[ch]).margin(1e-5));
    }
    // Equal depths: the lower index is in front.
    for (const bool red_first : {true, false}) {
        const RenderResult r = avsplat::render(make(2.0, 2.0, red_first), cam, o);
        const Eigen::Vector3d expect = red_first
                                           ? Eigen::Vector3d(a1 * red + (1 - a1) * a2 * green + (1 - a1) * (1 - a2) * bg)
                                           : Eigen::Vector3d(a2 * green + (1 - a2) * a1 * red + (1 - a1) * (1 - a2) * bg);
        for (int ch = 0; ch < 3; ++ch) CHECK(r.color[3 * centre + ch] == Approx(expect[ch]).margin(1e-5));
    }
}

TEST_CASE("render: transmittance stop and the 0.99 alpha cap", "[render]") {
    const int W = 17, H = 17;
    const Camera cam = axis_camera(W, H, 20.0, 8.5, 8.5);  // the axis hits pixel (8, 8)'s centre
    const std::size_t centre = 8 * W + 8;
    const RenderOptions o = with_precision(GENERATE(Precision::Float32, Precision::Float64));
    SECTION("opacity 0.95 five times: T = 0.05, 0.0025, 1.25e-4, then 6.25e-6 < 1e-4 stops") {
        GaussianCloud c(0, 0);
        for (int i = 0; i < 5; ++i)
            add_gaussian(c, Eigen::Vector3d(0, 0, 2.0 + i), Eigen::Vector3d(5, 5, 5), identity_quat(), 0.95,
                         Eigen::Vector3d(0.2 * i, 0.5, 1.0));
        const RenderResult r = avsplat::render(c, cam, o);
        CHECK(r.contributors[centre] == 3);
        CHECK(r.alpha[centre] == Approx(1 - 1.25e-4).margin(1e-6));
        const double w[3] = {0.95, 0.05 * 0.95, 0.0025 * 0.95};
        CHECK(r.color[3 * centre] == Approx(w[1] * 0.2 + w[2] * 0.4).margin(1e-6));
        CHECK(r.depth[centre] == Approx((w[0] * 2 + w[1] * 3 + w[2] * 4) / (1 - 1.25e-4)).epsilon(1e-6));
    }
    SECTION("opacity 1 gives alpha 0.99; opacity 0 gives nothing") {
        GaussianCloud c(0, 0);
        add_gaussian(c, Eigen::Vector3d(0, 0, 2), Eigen::Vector3d(5, 5, 5), identity_quat(), 1.0,
                     Eigen::Vector3d(1, 1, 1));
        add_gaussian(c, Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(5, 5, 5), identity_quat(), 0.0,
                     Eigen::Vector3d(0, 0, 0));
        const RenderResult r = avsplat::render(c, cam, o);
        CHECK(r.alpha[centre] == Approx(0.99).margin(1e-7));
        CHECK(r.contributors[centre] == 1);
        CHECK(r.stats.visible == 1);
        CHECK(r.depth[centre] == Approx(2.0).epsilon(1e-6));
    }
}

TEST_CASE("render: SH colour of degree 1..3 matches the real SH basis", "[render][sh]") {
    std::mt19937 rng(17);
    std::normal_distribution<double> g(0, 1);
    const int degree = GENERATE(1, 2, 3);
    const Precision precision = GENERATE(Precision::Float32, Precision::Float64);
    for (int trial = 0; trial < 20; ++trial) {
        const Eigen::Vector3d eye(3 * g(rng), 3 * g(rng), 3 * g(rng));
        const Eigen::Vector3d forward = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
        const Camera cam = Camera::look_at(eye, eye + forward, Eigen::Vector3d(0, 1, 0), 40.0, 17, 17);
        GaussianCloud c(0, degree);
        add_gaussian(c, eye + 2.0 * forward, Eigen::Vector3d(3, 3, 3), identity_quat(), 0.5,
                     Eigen::Vector3d(0.5, 0.5, 0.5));
        for (float& v : c.sh) v = float(0.4 * g(rng));
        const Eigen::Vector3d expect = reference_color(c, 0, eye);
        RenderOptions o;
        o.precision = precision;
        const RenderResult r = avsplat::render(c, cam, o);
        const std::size_t centre = 8 * 17 + 8;
        REQUIRE(r.alpha[centre] == Approx(0.5).margin(1e-6));
        for (int ch = 0; ch < 3; ++ch) REQUIRE(r.color[3 * centre + ch] == Approx(0.5 * expect[ch]).margin(2e-6));
    }
}

TEST_CASE("render: degree 0 gives the image of a higher degree with zero higher bands", "[render][sh]") {
    const GaussianCloud c3 = [] {
        GaussianCloud c = random_scene(300, 3, 0.9, 23);
        for (std::size_t i = 0; i < c.size(); ++i)
            for (int j = 3; j < 48; ++j) c.sh[i * 48 + j] = 0.0f;
        return c;
    }();
    GaussianCloud c0(c3.size(), 0);
    c0.means = c3.means;
    c0.scales = c3.scales;
    c0.rotations = c3.rotations;
    c0.opacities = c3.opacities;
    for (std::size_t i = 0; i < c3.size(); ++i)
        for (int ch = 0; ch < 3; ++ch) c0.sh[3 * i + ch] = c3.sh[48 * i + ch];
    const Camera cam = axis_camera(80, 60, 70.0, 40.0, 30.0);
    const RenderResult a = avsplat::render(c0, cam), b = avsplat::render(c3, cam);
    CHECK(a.color == b.color);
    CHECK(a.alpha == b.alpha);
    CHECK(a.contributors == b.contributors);
}

TEST_CASE("render: empty cloud gives the background", "[render]") {
    RenderOptions o;
    o.background = {0.25f, 0.5f, 0.75f};
    const RenderResult r = avsplat::render(GaussianCloud(0, 2), axis_camera(20, 10, 10, 10, 5), o);
    REQUIRE(r.color.size() == 600);
    for (std::size_t k = 0; k < 200; ++k) {
        CHECK(r.color[3 * k] == 0.25f);
        CHECK(r.color[3 * k + 1] == 0.5f);
        CHECK(r.color[3 * k + 2] == 0.75f);
        CHECK(r.alpha[k] == 0.0f);
        CHECK(r.depth[k] == 0.0f);
        CHECK(r.contributors[k] == 0);
    }
    CHECK(r.stats.visible == 0);
}

// =============================================================================================
// Rendering against the brute-force reference

TEST_CASE("render agrees with a brute-force renderer where the box cannot matter", "[render]") {
    // Opacity <= 0.35: outside its 3-sigma box a splat has alpha < 0.35 e^-4.5 < 1/255, so the
    // brute force, which ignores boxes and tiles, must give the same image.
    const int degree = GENERATE(0, 3);
    const bool antialiased = GENERATE(false, true);
    GaussianCloud c = random_scene(250, degree, 0.35, 31 + std::uint32_t(degree));
    // A few behind the camera, straddling z = 0, and far outside the view (Jacobian clamp).
    for (std::size_t i = 0; i < 10; ++i) c.means[3 * i + 2] = -c.means[3 * i + 2];
    for (std::size_t i = 10; i < 20; ++i) c.means[3 * i] *= 4.0f;
    const Camera cam = Camera(55.0, 50.0, 37.0, 26.0, 75, 53);
    RenderOptions o;
    o.antialiased = antialiased;
    o.background = {0.3f, 0.1f, 0.6f};
    const RefImage ref = reference_render(c, cam, o, false);
    for (const Precision p : {Precision::Float64, Precision::Float32}) {
        o.precision = p;
        const RenderResult r = avsplat::render(c, cam, o);
        const Diff d = compare(r, ref);
        INFO("precision " << (p == Precision::Float64 ? "float64" : "float32") << ": max colour error "
                          << d.max_color << ", mean " << d.mean_color << ", max alpha error " << d.max_alpha
                          << ", max relative depth error " << d.max_depth_rel);
        // float64: the float32 rounding of the outputs; float32: its arithmetic.
        const double tol = p == Precision::Float64 ? 1e-7 : 5e-6;
        CHECK(d.max_color < tol);
        CHECK(d.max_alpha < tol);
        // Depth divides by alpha = 1 - T, which float32 holds to ~6e-8 absolute (see above).
        CHECK(d.max_depth_rel < (p == Precision::Float64 ? 1e-7 : 3e-5));
        CHECK(d.contributor_mismatches == 0);
    }
}

TEST_CASE("render applies the radius rule: high opacities are cut at the box", "[render]") {
    // Opaque splats are still above 1/255 at 3 sigma, so the box decides where they end: the
    // brute force applying the same box agrees, the one without boxes does not.
    GaussianCloud c = random_scene(120, 0, 1.0, 41);
    for (float& o : c.opacities) o = 0.6f + 0.4f * o;
    const Camera cam = Camera(55.0, 50.0, 37.0, 26.0, 75, 53);
    RenderOptions o;
    o.precision = Precision::Float64;
    const RenderResult r = avsplat::render(c, cam, o);
    const Diff with_box = compare(r, reference_render(c, cam, o, true));
    CHECK(with_box.max_color < 1e-7);
    CHECK(with_box.max_alpha < 1e-7);
    CHECK(with_box.contributor_mismatches == 0);
    const Diff without_box = compare(r, reference_render(c, cam, o, false));
    CHECK(without_box.contributor_mismatches > 0);
}

TEST_CASE("render: float32 against float64 on random scenes", "[render]") {
    double worst_max = 0, worst_mean = 0, worst_alpha = 0;
    long flipped = 0, pixels = 0;
    for (std::uint32_t seed = 0; seed < 3; ++seed) {
        const GaussianCloud c = random_scene(3000, 3, 1.0, 100 + seed, 0.01, 0.2);
        const Camera cam = Camera::look_at(Eigen::Vector3d(0.3 * seed, -0.2, -0.5), Eigen::Vector3d(0, 0, 4),
                                           Eigen::Vector3d(0, -1, 0), 70.0, 160, 120);
        const RenderResult a = avsplat::render(c, cam, with_precision(Precision::Float32));
        const RenderResult b = avsplat::render(c, cam, with_precision(Precision::Float64));
        double max_e = 0, sum_e = 0;
        for (std::size_t k = 0; k < a.color.size(); ++k) {
            const double e = std::abs(double(a.color[k]) - b.color[k]);
            max_e = std::max(max_e, e);
            sum_e += e;
        }
        for (std::size_t k = 0; k < a.alpha.size(); ++k) {
            worst_alpha = std::max(worst_alpha, double(std::abs(a.alpha[k] - b.alpha[k])));
            flipped += a.contributors[k] != b.contributors[k];
        }
        pixels += long(a.alpha.size());
        worst_max = std::max(worst_max, max_e);
        worst_mean = std::max(worst_mean, sum_e / double(a.color.size()));
    }
    WARN("float32 vs float64 on 3 random scenes of 3000 Gaussians, SH degree 3, 160x120: max colour error "
         << worst_max << ", mean " << worst_mean << ", max alpha error " << worst_alpha << ", pixels whose "
         << "contributor count differs " << flipped << "/" << pixels);
    // Mean error at float rounding level; the maximum can reach a threshold decision (alpha
    // near 1/255, a box edge or the transmittance stop) that rounds the other way.
    CHECK(worst_mean < 2e-6);
    CHECK(worst_max < 1e-2);
    CHECK(flipped <= pixels / 1000);
}

// =============================================================================================
// Determinism

TEST_CASE("render does not depend on the number of threads or the order of the input", "[render]") {
    const GaussianCloud c = random_scene(4000, 2, 1.0, 7);
    const Camera cam = axis_camera(150, 110, 90.0, 75.0, 55.0);
    const int saved = omp_get_max_threads();
    omp_set_num_threads(1);
    const RenderResult one = avsplat::render(c, cam);
    omp_set_num_threads(3);
    const RenderResult three = avsplat::render(c, cam);
    omp_set_num_threads(saved);
    CHECK(one.stats.threads == 1);
    CHECK(three.stats.threads == 3);
    CHECK(one.color == three.color);
    CHECK(one.alpha == three.alpha);
    CHECK(one.depth == three.depth);
    CHECK(one.contributors == three.contributors);
    CHECK(one.stats.blends == three.stats.blends);

    // Depths are distinct, so a permutation of the Gaussians gives the same image, bit for bit.
    std::vector<std::size_t> perm(c.size());
    std::iota(perm.begin(), perm.end(), 0);
    std::shuffle(perm.begin(), perm.end(), std::mt19937(99));
    const RenderResult shuffled = avsplat::render(avsplat::select(c, perm), cam);
    CHECK(shuffled.color == one.color);
    CHECK(shuffled.alpha == one.alpha);
    CHECK(shuffled.depth == one.depth);
    CHECK(shuffled.contributors == one.contributors);
}

// =============================================================================================
// Stiff and extreme inputs

namespace {

/// Finite outputs, alpha in [0, 1], depth >= 0, and every colour channel within the range of
/// the Gaussians' colours and the background (a composite is a convex combination of them).
void check_sane(const RenderResult& r, const GaussianCloud& c, const RenderOptions& o) {
    REQUIRE(all_finite(r.color));
    REQUIRE(all_finite(r.alpha));
    REQUIRE(all_finite(r.depth));
    double lo[3], hi[3];
    for (int ch = 0; ch < 3; ++ch) lo[ch] = hi[ch] = o.background[ch];
    for (std::size_t i = 0; i < c.size(); ++i)
        for (int ch = 0; ch < 3; ++ch) {
            const double v = std::max(0.5 + kC0 * c.sh[i * std::size_t(c.sh_coeffs()) * 3 + ch], 0.0);
            lo[ch] = std::min(lo[ch], v);
            hi[ch] = std::max(hi[ch], v);
        }
    for (std::size_t k = 0; k < r.alpha.size(); ++k) {
        REQUIRE(r.alpha[k] >= 0.0f);
        REQUIRE(r.alpha[k] <= 1.0f);
        REQUIRE(r.depth[k] >= 0.0f);
        REQUIRE(r.contributors[k] >= 0);
        for (int ch = 0; ch < 3; ++ch) {
            REQUIRE(r.color[3 * k + ch] >= lo[ch] - 1e-5);
            REQUIRE(r.color[3 * k + ch] <= hi[ch] + 1e-5);
        }
    }
}

GaussianCloud stiff_scene(const std::vector<Eigen::Vector3d>& scales, double z, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> g(0, 1);
    std::uniform_real_distribution<double> u(0, 1);
    GaussianCloud c(0, 0);
    for (const Eigen::Vector3d& s : scales)
        for (int rep = 0; rep < 20; ++rep)
            add_gaussian(c, Eigen::Vector3d(0.5 * g(rng), 0.5 * g(rng), z + 0.3 * g(rng)), s,
                         Eigen::Vector4d(g(rng), g(rng), g(rng), g(rng)), rep % 5 == 0 ? 1.0 : u(rng),
                         Eigen::Vector3d(u(rng), u(rng), u(rng)));
    return c;
}

// Gaussians at 1.001, 0.999 and exactly 1 x near, at the camera centre, behind and in front,
// with the camera inside a large Gaussian: the near-plane rule and its ties.
GaussianCloud near_plane_scene(const Camera& cam) {
    GaussianCloud c(0, 0);
    for (const double z : {cam.near * 1.001, cam.near * 0.999, cam.near, 0.0, -0.3, 0.3})
        add_gaussian(c, Eigen::Vector3d(0.001, -0.002, z), Eigen::Vector3d(0.5, 0.2, 1.0),
                     Eigen::Vector4d(0.9, 0.1, 0.3, 0.2), 0.8, Eigen::Vector3d(0.9, 0.1, 0.5));
    add_gaussian(c, Eigen::Vector3d(0, 0, 0.05), Eigen::Vector3d(2, 2, 2), identity_quat(), 0.5,
                 Eigen::Vector3d(0.1, 0.9, 0.1));
    return c;
}

}  // namespace

TEST_CASE("render: stiff and extreme Gaussians give sane images", "[render][stress]") {
    const Camera cam = axis_camera(64, 48, 50.0, 32.0, 24.0);
    RenderOptions o;
    o.background = {0.2f, 0.4f, 0.6f};
    o.precision = GENERATE(Precision::Float32, Precision::Float64);
    o.antialiased = GENERATE(false, true);
    SECTION("needles and pancakes: scale ratios of 1e6") {
        const GaussianCloud c = stiff_scene({{1, 1e-6, 1e-6}, {1e-6, 1, 1e-6}, {1, 1, 1e-6}, {1e-6, 1, 1}}, 3.0, 1);
        check_sane(avsplat::render(c, cam, o), c, o);
    }
    SECTION("scales of 1e-8 and 1e4") {
        const GaussianCloud c = stiff_scene({{1e-8, 1e-8, 1e-8}, {1e4, 1e4, 1e4}, {1e4, 1e-8, 1}}, 3.0, 2);
        check_sane(avsplat::render(c, cam, o), c, o);
    }
    SECTION("Gaussians straddling the near plane and the camera inside a Gaussian") {
        const GaussianCloud c = near_plane_scene(cam);
        const RenderResult r = avsplat::render(c, cam, o);
        check_sane(r, c, o);
        CHECK(r.alpha[24 * 64 + 32] > 0.5f);  // the Gaussian around the camera covers the view
    }
    SECTION("opacity 0 and 1 only") {
        GaussianCloud c = stiff_scene({{0.1, 0.2, 0.3}}, 3.0, 3);
        for (std::size_t i = 0; i < c.size(); ++i) c.opacities[i] = float(i % 2);
        const RenderResult r = avsplat::render(c, cam, o);
        check_sane(r, c, o);
        CHECK(r.stats.visible <= c.size() / 2);
    }
}

TEST_CASE("render: 1e5 Gaussians in one tile", "[render][stress]") {
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> u(0, 1);
    GaussianCloud c(0, 0);
    // All within the first 16 x 16 tile of the image, faint (but above 1/255, so none is culled).
    for (int i = 0; i < 100000; ++i)
        add_gaussian(c, Eigen::Vector3d((16 * u(rng) - 32) / 50.0 * 4, (16 * u(rng) - 24) / 50.0 * 4, 4.0 + 0.01 * u(rng)),
                     Eigen::Vector3d(0.01, 0.02, 0.01), identity_quat(), 0.004 + 0.016 * u(rng),
                     Eigen::Vector3d(u(rng), u(rng), u(rng)));
    const Camera cam = axis_camera(64, 48, 50.0, 32.0, 24.0);
    RenderOptions o;
    const RenderResult r = avsplat::render(c, cam, o);
    check_sane(r, c, o);
    CHECK(r.stats.visible == 100000);
    CHECK(r.alpha[5 * 64 + 5] > 0.5f);
    CHECK(r.alpha[40 * 64 + 60] == 0.0f);
}

TEST_CASE("render: coordinates of 1e6 with the camera near them", "[render][stress]") {
    // Offsets that are multiples of 1/16 are exact in float32 at 1e6 (whose spacing is 1/16),
    // so the scene translated to the origin is the same scene.
    std::mt19937 rng(8);
    std::uniform_int_distribution<int> step(-16, 16);
    GaussianCloud near_origin(0, 0), far_away(0, 0);
    const Eigen::Vector3d base(1e6, -1e6, 1e6);
    for (int i = 0; i < 200; ++i) {
        const Eigen::Vector3d off(step(rng) / 16.0, step(rng) / 16.0, step(rng) / 16.0);
        const Eigen::Vector3d s(0.05 + 0.1 * (i % 3), 0.1, 0.07);
        const Eigen::Vector4d q(1, 0.1 * (i % 5), 0.2, -0.1);
        const Eigen::Vector3d rgb(0.1 * (i % 10), 0.5, 1.0 - 0.1 * (i % 10));
        add_gaussian(near_origin, off, s, q, 0.7, rgb);
        add_gaussian(far_away, base + off, s, q, 0.7, rgb);
    }
    const Eigen::Vector3d eye(0.3, -0.4, -3.0);
    const Camera cam0 = Camera::look_at(eye, Eigen::Vector3d::Zero(), Eigen::Vector3d(0, -1, 0), 60.0, 64, 48);
    const Camera cam1 = Camera::look_at(base + eye, base, Eigen::Vector3d(0, -1, 0), 60.0, 64, 48);
    RenderOptions o;
    const RenderResult a = avsplat::render(near_origin, cam0, o), b = avsplat::render(far_away, cam1, o);
    check_sane(b, far_away, o);
    double worst = 0;
    for (std::size_t k = 0; k < a.color.size(); ++k) worst = std::max(worst, double(std::abs(a.color[k] - b.color[k])));
    CHECK(worst < 1e-4);
    CHECK(*std::max_element(b.alpha.begin(), b.alpha.end()) > 0.5f);
}

namespace {

/// Renders `c` in float32 and float64 and requires the same culling (visible count, tile
/// instances, per-pixel contributor counts) and colours and alphas within 1e-3.
void check_precisions_agree(const GaussianCloud& c, const Camera& cam, RenderOptions o) {
    o.precision = Precision::Float32;
    const RenderResult a = avsplat::render(c, cam, o);
    o.precision = Precision::Float64;
    const RenderResult b = avsplat::render(c, cam, o);
    CHECK(a.stats.visible == b.stats.visible);
    CHECK(a.stats.tile_instances == b.stats.tile_instances);
    double color_err = 0, alpha_err = 0;
    for (std::size_t k = 0; k < a.color.size(); ++k)
        color_err = std::max(color_err, std::abs(double(a.color[k]) - double(b.color[k])));
    for (std::size_t k = 0; k < a.alpha.size(); ++k)
        alpha_err = std::max(alpha_err, std::abs(double(a.alpha[k]) - double(b.alpha[k])));
    INFO("visible " << a.stats.visible << " (float32), " << b.stats.visible << " (float64); max colour error "
                    << color_err << ", max alpha error " << alpha_err);
    CHECK(color_err <= 1e-3);
    CHECK(alpha_err <= 1e-3);
}

}  // namespace

// Culling must not depend on the precision: a needle of 1e4 x 1e-8 x 1 has a 3D covariance
// whose entries are ~1e8 while its 2D footprint's short axis comes from the axis of length 1,
// below the rounding error of float32 entries; float32 used to call such needles degenerate
// and cull them (14 of 20 visible against 20 in float64).
TEST_CASE("render: float32 and float64 cull the same stiff Gaussians", "[render][stress]") {
    const Camera cam = axis_camera(64, 48, 50.0, 32.0, 24.0);
    RenderOptions o;
    o.background = {0.2f, 0.4f, 0.6f};
    o.antialiased = GENERATE(false, true);
    SECTION("needles of 1e4 x 1e-8 x 1") {
        check_precisions_agree(stiff_scene({{1e4, 1e-8, 1}}, 3.0, 2), cam, o);
    }
    SECTION("scales of 1e-8 and 1e4") {
        check_precisions_agree(stiff_scene({{1e-8, 1e-8, 1e-8}, {1e4, 1e4, 1e4}, {1e4, 1e-8, 1}}, 3.0, 2), cam, o);
    }
    SECTION("needles and pancakes: scale ratios of 1e6") {
        check_precisions_agree(
            stiff_scene({{1, 1e-6, 1e-6}, {1e-6, 1, 1e-6}, {1, 1, 1e-6}, {1e-6, 1, 1}}, 3.0, 1), cam, o);
    }
    SECTION("Gaussians straddling the near plane and the camera inside a Gaussian") {
        const GaussianCloud c = near_plane_scene(cam);
        check_precisions_agree(c, cam, o);
    }
}

// The near-plane rule (projection.h): kept when near <= z, with z the double camera-space depth
// of the float32 mean and near the camera's double. A mean stored as 0.01f lies below a near
// plane of 0.01 (0.01f = 0.0099999998), so it is culled in both precisions; at near = 0.01f
// exactly it is a tie, which is kept.
TEST_CASE("render: the near-plane test compares the stored mean with the camera's near plane", "[render]") {
    const float z = 0.01f;
    GaussianCloud c(0, 0);
    add_gaussian(c, Eigen::Vector3d(0, 0, z), Eigen::Vector3d(0.05, 0.05, 0.05), identity_quat(), 0.9,
                 Eigen::Vector3d(0.9, 0.1, 0.5));
    const Precision precision = GENERATE(Precision::Float32, Precision::Float64);
    const RenderOptions o = with_precision(precision);
    auto visible = [&](double near) {
        return avsplat::render(c, Camera(50, 50, 32, 24, 64, 48, Eigen::Matrix4d::Identity(), near), o).stats.visible;
    };
    CHECK(visible(0.01) == 0);
    CHECK(visible(double(z)) == 1);
    CHECK(visible(std::nextafter(double(z), 0.0)) == 1);
    CHECK(visible(std::nextafter(double(z), 1.0)) == 0);
}

// =============================================================================================
// Errors

TEST_CASE("render rejects bad input, naming the field", "[render]") {
    const GaussianCloud c = random_scene(10, 0, 1.0, 1);
    const Camera cam = axis_camera(16, 16, 10, 8, 8);
    auto fails_with = [&](RenderOptions o, const char* what) {
        REQUIRE_THROWS_WITH(avsplat::render(c, cam, o), Contains(what));
        REQUIRE_THROWS_AS(avsplat::render(c, cam, o), std::invalid_argument);
    };
    RenderOptions o;
    o.alpha_threshold = 0.0f;
    fails_with(o, "RenderOptions.alpha_threshold");
    o = RenderOptions();
    o.transmittance_stop = 1.0f;
    fails_with(o, "RenderOptions.transmittance_stop");
    o = RenderOptions();
    o.extent_sigma = -1.0f;
    fails_with(o, "RenderOptions.extent_sigma");
    o = RenderOptions();
    o.low_pass = std::numeric_limits<float>::quiet_NaN();
    fails_with(o, "RenderOptions.low_pass");
    o = RenderOptions();
    o.background[1] = std::numeric_limits<float>::infinity();
    fails_with(o, "RenderOptions.background[1]");

    GaussianCloud bad = c;
    bad.scales[3 * 4 + 1] = -1.0f;
    REQUIRE_THROWS_WITH(avsplat::render(bad, cam), Contains("scales") && Contains("4"));
    Camera bad_cam = cam;
    bad_cam.fx = 0.0;
    REQUIRE_THROWS_WITH(avsplat::render(c, bad_cam), Contains("fx"));
}

TEST_CASE("render with Backend::Cuda renders or reports that CUDA is unavailable", "[render]") {
    const GaussianCloud c = random_scene(10, 0, 1.0, 1);
    RenderOptions o;
    o.backend = avsplat::Backend::Cuda;
    try {
        const RenderResult r = avsplat::render(c, axis_camera(16, 16, 10, 8, 8), o);
        CHECK(r.alpha.size() == 256u);
    } catch (const avsplat::DeviceError& e) {
        CHECK_THAT(e.what(), Contains("CUDA"));
    }
}
