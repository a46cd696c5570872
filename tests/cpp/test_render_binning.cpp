// Tests of the CPU renderer's sorting and binning and of RenderWorkspace (render.h): the
// renderer's images against a brute-force compositor that, per pixel, takes every visible
// splat whose box holds the pixel in (float depth, index) order from a std::sort and applies
// blend.h's steps. The brute force uses the very records project_record writes and the same
// float operations as the tile kernels, so any error in the depth sort, the compaction of the
// visible splats or the tile lists changes bits; the comparison is exact. Scenes with many equal
// depths (ties broken by index) and with depths over a wide range (many sort digits) included.
// Then: renders that reuse one workspace equal fresh renders bit for bit, across clouds, sizes,
// precisions, thread counts and contributions.
#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"
#include "render/cpu/tile_state.h"
#include "render/shared/blend.h"
#include "render/shared/project_and_shade.h"
#include "render/shared/tiling.h"
#include "render/shared/view_params.h"

#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <stdexcept>
#include <vector>

using avsplat::Camera;
using avsplat::GaussianCloud;
using avsplat::RenderOptions;
using avsplat::RenderResult;

namespace {

/// n Gaussians of SH degree 1 in [-1, 1]^2 x [z_lo, z_hi] (log-uniform depth), log-uniform scales
/// in [s_lo, s_hi]. With `groups` > 0, Gaussians come in groups of `groups` sharing one mean (so
/// one depth) with different colours and shapes: ties the sort must break by index.
GaussianCloud scene(std::size_t n, std::uint32_t seed, double z_lo, double z_hi, double s_lo, double s_hi,
                    int groups) {
    GaussianCloud c(n, 1);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0), op(0.05, 1.0), lz(std::log(z_lo), std::log(z_hi)),
        ls(std::log(s_lo), std::log(s_hi));
    std::normal_distribution<float> g(0.0f, 1.0f);
    const int k = c.sh_coeffs();
    double mean[3] = {0, 0, 0};
    for (std::size_t i = 0; i < n; ++i) {
        if (groups <= 0 || i % std::size_t(groups) == 0) {
            const double z = std::exp(lz(rng));
            mean[0] = 0.8 * z * u(rng);  // within the 90-degree view
            mean[1] = 0.5 * z * u(rng);
            mean[2] = z;
        }
        for (int j = 0; j < 3; ++j) c.means[3 * i + j] = float(mean[j]);
        const double s = std::exp(ls(rng)) * mean[2];  // a size that stays visible at any depth
        for (int j = 0; j < 3; ++j) c.scales[3 * i + j] = float(s * (0.5 + 0.5 * (u(rng) + 1.0)));
        for (int j = 0; j < 4; ++j) c.rotations[4 * i + j] = g(rng);
        c.opacities[i] = float(op(rng));
        for (int j = 0; j < 3 * k; ++j) c.sh[i * 3 * k + j] = (j < 3 ? 1.0f : 0.2f) * g(rng);
    }
    return c;
}

/// Looks down +z from the origin.
Camera front_camera(int w, int h) {
    return Camera::look_at(Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0, -1, 0), 70.0, w, h);
}

struct Visible {
    std::uint32_t depth_bits;
    std::uint32_t index;
};

/// The brute-force image: every pixel composites, front to back in (float depth, index) order, the
/// visible splats whose box holds it, with blend.h's functions, as the tile kernels do.
template <class T>
RenderResult brute_force(const GaussianCloud& c, const Camera& cam, const RenderOptions& o) {
    using Record = avsplat::detail::cpu::SplatRecord<T>;
    const auto view = avsplat::preprocess::view_params<T>(cam, o, c.sh_degree);
    std::vector<Record> rec(c.size());
    std::vector<Visible> vis;
    const int k = c.sh_coeffs();
    for (std::size_t i = 0; i < c.size(); ++i) {
        if (avsplat::preprocess::project_record(view, &c.means[3 * i], &c.scales[3 * i], &c.rotations[4 * i],
                                                c.opacities[i], &c.sh[i * std::size_t(k) * 3], rec[i]) == 0)
            continue;
        vis.push_back({avsplat::tiling::depth_bits(float(rec[i].depth)), std::uint32_t(i)});
    }
    std::sort(vis.begin(), vis.end(), [](const Visible& a, const Visible& b) {
        return a.depth_bits != b.depth_bits ? a.depth_bits < b.depth_bits : a.index < b.index;
    });
    RenderResult r;
    r.width = cam.width;
    r.height = cam.height;
    const std::size_t np = std::size_t(cam.width) * std::size_t(cam.height);
    r.color.resize(3 * np);
    r.alpha.resize(np);
    r.depth.resize(np);
    r.contributors.resize(np);
    const T bg[3] = {T(o.background[0]), T(o.background[1]), T(o.background[2])};
    for (int y = 0; y < cam.height; ++y)
        for (int x = 0; x < cam.width; ++x) {
            T tr = T(1), sum[3] = {0, 0, 0}, dsum = 0;
            std::int32_t count = 0;
            for (const Visible& v : vis) {
                const Record& s = rec[v.index];
                if (x < s.x_min || x > s.x_max || y < s.y_min || y > s.y_max) continue;
                ++r.stats.blends;
                const T dx = (T(x) + T(0.5)) - s.mean_x, dy = (T(y) + T(0.5)) - s.mean_y;
                const T alpha = avsplat::blend::splat_alpha(s.opacity, avsplat::blend::gaussian_power(
                                                                            s.conic_a, s.conic_b, s.conic_c, dx, dy));
                const auto step = avsplat::blend::blend_step(alpha, tr, T(o.alpha_threshold), T(o.transmittance_stop));
                if (step.saturated) break;
                for (int ch = 0; ch < 3; ++ch) sum[ch] += step.weight * s.rgb[ch];
                dsum += step.weight * s.depth;
                tr = step.next_transmittance;
                count += step.blended;
            }
            T rgb[3], alpha, depth;
            avsplat::blend::finish_pixel(tr, sum, dsum, bg, rgb, alpha, depth);
            const std::size_t p = std::size_t(y) * std::size_t(cam.width) + std::size_t(x);
            for (int ch = 0; ch < 3; ++ch) r.color[3 * p + ch] = float(rgb[ch]);
            r.alpha[p] = float(alpha);
            r.depth[p] = float(depth);
            r.contributors[p] = count;
        }
    r.stats.visible = vis.size();
    return r;
}

void check_same_bits(const RenderResult& a, const RenderResult& b) {
    REQUIRE(a.color.size() == b.color.size());
    REQUIRE(a.alpha.size() == b.alpha.size());
    CHECK(std::memcmp(a.color.data(), b.color.data(), a.color.size() * sizeof(float)) == 0);
    CHECK(std::memcmp(a.alpha.data(), b.alpha.data(), a.alpha.size() * sizeof(float)) == 0);
    CHECK(std::memcmp(a.depth.data(), b.depth.data(), a.depth.size() * sizeof(float)) == 0);
    CHECK(a.contributors == b.contributors);
    CHECK(a.stats.blends == b.stats.blends);
    CHECK(a.stats.visible == b.stats.visible);
}

void check_same(const RenderResult& a, const RenderResult& b) {
    check_same_bits(a, b);
    CHECK(a.stats.tile_instances == b.stats.tile_instances);
    CHECK(a.stats.contributions == b.stats.contributions);
    CHECK(a.has_gaussian_contributions == b.has_gaussian_contributions);
    CHECK(a.contribution_max == b.contribution_max);
    CHECK(a.contribution_sum == b.contribution_sum);
}

}  // namespace

TEST_CASE("render: sorting and binning give the brute-force image bit for bit", "[render][binning]") {
    struct Case {
        const char* name;
        GaussianCloud cloud;
    };
    const std::vector<Case> cases = {
        {"random", scene(3000, 1, 2.0, 6.0, 0.002, 0.02, 0)},
        {"equal depths in groups of 7", scene(2100, 2, 2.0, 6.0, 0.002, 0.03, 7)},
        {"depths over 0.05 .. 5e4", scene(3000, 3, 0.05, 5e4, 0.001, 0.02, 0)},
        {"one depth for all", scene(500, 4, 3.0, 3.0, 0.01, 0.05, 500)},
    };
    const Camera cam = front_camera(75, 53);  // partial tiles on both edges
    const int saved = omp_get_max_threads();
    for (const Case& c : cases) {
        for (const int threads : {1, 3}) {
            omp_set_num_threads(threads);
            RenderOptions o;
            o.background = {0.1f, 0.2f, 0.3f};
            INFO(c.name << ", " << threads << " threads");
            const RenderResult f = avsplat::render(c.cloud, cam, o);
            CHECK(f.stats.visible > c.cloud.size() / 2);
            check_same_bits(f, brute_force<float>(c.cloud, cam, o));
            o.precision = avsplat::Precision::Float64;
            check_same_bits(avsplat::render(c.cloud, cam, o), brute_force<double>(c.cloud, cam, o));
        }
    }
    omp_set_num_threads(saved);
}

TEST_CASE("RenderWorkspace: renders reusing one equal fresh renders bit for bit", "[render][binning]") {
    const GaussianCloud big = scene(4000, 5, 1.0, 8.0, 0.002, 0.03, 0);
    const GaussianCloud small = scene(300, 6, 2.0, 3.0, 0.01, 0.05, 3);
    const GaussianCloud empty(0, 0);
    const Camera wide = front_camera(160, 90), narrow = front_camera(33, 70);
    RenderOptions contrib;
    contrib.gaussian_contributions = true;
    RenderOptions f64;
    f64.precision = avsplat::Precision::Float64;
    struct Step {
        const GaussianCloud* cloud;
        const Camera* cam;
        RenderOptions options;
        int threads;
    };
    // Large then small then large again (stale contents of a larger buffer must not leak), both
    // precisions, contributions, thread counts.
    const std::vector<Step> steps = {
        {&big, &wide, {}, 2},     {&small, &narrow, {}, 1}, {&big, &narrow, contrib, 3}, {&empty, &wide, {}, 2},
        {&small, &wide, f64, 2},  {&big, &wide, f64, 1},    {&small, &narrow, contrib, 2}, {&big, &wide, {}, 1},
    };
    const int saved = omp_get_max_threads();
    avsplat::RenderWorkspace ws;
    CHECK(ws.bytes() == 0);
    std::size_t held = 0;
    for (std::size_t k = 0; k < steps.size(); ++k) {
        INFO("step " << k);
        const Step& s = steps[k];
        omp_set_num_threads(s.threads);
        const RenderResult reused = avsplat::render(*s.cloud, *s.cam, s.options, ws);
        const RenderResult fresh = avsplat::render(*s.cloud, *s.cam, s.options);
        check_same(reused, fresh);
        CHECK(ws.bytes() >= held);  // it only grows
        held = ws.bytes();
    }
    omp_set_num_threads(saved);
    CHECK(held > 4000 * sizeof(avsplat::detail::cpu::SplatRecord<double>));
    ws.release();
    CHECK(ws.bytes() == 0);
    check_same(avsplat::render(big, wide, {}, ws), avsplat::render(big, wide, {}));
    // A moved-to workspace takes the memory; the moved-from one stays usable.
    avsplat::RenderWorkspace other = std::move(ws);
    CHECK(other.bytes() > 0);
    check_same(avsplat::render(small, narrow, {}, ws), avsplat::render(small, narrow, {}));
    // Bad input is refused as without a workspace, and the workspace stays usable.
    RenderOptions bad;
    bad.alpha_threshold = 2.0f;
    CHECK_THROWS_AS(avsplat::render(small, narrow, bad, other), std::invalid_argument);
    check_same(avsplat::render(small, narrow, {}, other), avsplat::render(small, narrow, {}));
}

TEST_CASE("RenderWorkspace: a render while another uses the workspace is refused", "[render][binning]") {
    const GaussianCloud c = scene(200, 7, 2.0, 3.0, 0.01, 0.05, 0);
    const Camera cam = front_camera(64, 48);
    avsplat::RenderWorkspace ws;
    // Renders on many threads at once: each either succeeds with the fresh image or is refused
    // with std::logic_error; none may race on the buffers.
    const RenderResult expected = avsplat::render(c, cam);
    int refused = 0, done = 0;
    const int saved = omp_get_max_threads();
#pragma omp parallel num_threads(4) reduction(+ : refused, done)
    {
        omp_set_num_threads(1);  // each render single-threaded
        for (int rep = 0; rep < 20; ++rep) {
            try {
                const RenderResult r = avsplat::render(c, cam, {}, ws);
                if (r.color == expected.color && r.contributors == expected.contributors) ++done;
            } catch (const std::logic_error&) {
                ++refused;
            }
        }
    }
    omp_set_num_threads(saved);
    CHECK(done + refused == 80);
    CHECK(done >= 1);
}
