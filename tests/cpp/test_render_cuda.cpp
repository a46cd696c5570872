// Tests of the CUDA renderer.
//
// Everywhere (tag [render_cuda], ctest label "cpp"): the kernels' per-thread bodies
// (lib/src/render/cuda/kernel_bodies.h) and the host orchestration (launch_plan.h, kernel_params.h) run on the
// host. A whole frame is assembled from them as the GPU assembles it (project, scan, emit keys,
// stable sort, tile ranges, per-tile batches with early termination) and held to the CPU
// renderer; the pieces are held to tiling.h, validate() and hand-computed cases. Also the
// errors of backend Cuda when the renderer or a device is missing.
//
// With a GPU (tag [gpu], ctest label "gpu"): the CUDA renderer against the CPU renderer in
// float32 (max abs error <= 1e-4 on colour and alpha, identical contributor counts) and float64,
// host and device-pointer inputs, and device-side validation. Without a device these print
// "SKIPPED: no CUDA device" and pass (ctest reports them as skipped).
#include "avsplat/core/camera.h"
#include "avsplat/core/error.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"
#include "avsplat/render/render_cuda.h"
#include "render/shared/tiling.h"

#include "render/cuda/kernel_params.h"
#include "render/cuda/launch_plan.h"
#include "render/cuda/kernel_bodies.h"

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#ifdef AVSPLAT_TEST_CUDA
#include <cuda_runtime_api.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <iterator>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using avsplat::Backend;
using avsplat::Camera;
using avsplat::GaussianCloud;
using avsplat::Precision;
using avsplat::RenderOptions;
using avsplat::RenderResult;
namespace gpu = avsplat::gpu;
namespace tiling = avsplat::tiling;

namespace {

// ---- scenes ------------------------------------------------------------------------------

void set_rotation(GaussianCloud& c, std::size_t i, float w, float x, float y, float z) {
    c.rotations[4 * i] = w;
    c.rotations[4 * i + 1] = x;
    c.rotations[4 * i + 2] = y;
    c.rotations[4 * i + 3] = z;
}

/// n Gaussians of SH degree `degree` around the origin: random positions (some behind the
/// camera of random_camera, some outside its view), rotations (not normalised), anisotropic
/// scales, opacities in [0, 1] and SH.
GaussianCloud random_scene(std::size_t n, int degree, std::uint32_t seed) {
    GaussianCloud c(n, degree);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> pos(-1.6f, 1.6f), log_s(std::log(0.004f), std::log(0.25f)),
        unit(0.0f, 1.0f);
    std::normal_distribution<float> g(0.0f, 1.0f);
    const int k = c.sh_coeffs();
    for (std::size_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            c.means[3 * i + a] = pos(rng);
            c.scales[3 * i + a] = std::exp(log_s(rng));
        }
        set_rotation(c, i, g(rng), g(rng), g(rng), 2.0f * g(rng));
        c.opacities[i] = unit(rng);
        for (int j = 0; j < k; ++j)
            for (int a = 0; a < 3; ++a) c.sh[(i * k + j) * 3 + a] = (j == 0 ? 1.2f : 0.3f) * g(rng);
    }
    return c;
}

/// A camera 3.5 units from the origin looking at it, with an image size that is not a multiple
/// of the tile size.
Camera random_camera(int width = 157, int height = 93) {
    return Camera::look_at(Eigen::Vector3d(2.1, -0.7, 2.8), Eigen::Vector3d(0.05, 0.0, 0.0),
                           Eigen::Vector3d(0, 1, 0), 55.0, width, height, 0.2, 6.0);
}

/// The cases at the edges of the rules, seen by extreme_camera (identity pose, looking down +z,
/// near 0.1, far 50): needles, zero and huge scales, a splat covering the whole image, means on
/// the near and far planes and beyond them, behind the camera and far outside the image,
/// opacities 0 and 1, coincident splats (depth ties, broken by index), a stack that saturates
/// pixels, and an unnormalised quaternion.
GaussianCloud extreme_scene() {
    struct G {
        float x, y, z, sx, sy, sz, opacity, r, g, b;
        float qw = 1, qx = 0, qy = 0, qz = 0;
    };
    std::vector<G> gs;
    gs.push_back({0.0f, 0.0f, 5.0f, 1e-4f, 2.0f, 1e-4f, 0.9f, 1, 0, 0, 0.9f, 0.1f, 0.3f, 0.2f});  // needle
    gs.push_back({0.3f, -0.2f, 4.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0, 1, 0});       // zero scale: low-pass only
    gs.push_back({0.0f, 0.0f, 30.0f, 200.0f, 150.0f, 1.0f, 0.6f, 0, 0, 1});   // covers the image
    gs.push_back({0.0f, 0.0f, 0.1f, 0.01f, 0.01f, 0.01f, 0.8f, 1, 1, 0});     // on the near plane
    gs.push_back({0.0f, 0.0f, 0.0999f, 0.05f, 0.05f, 0.05f, 1.0f, 1, 0, 1});  // just in front of it
    gs.push_back({0.0f, 0.0f, -2.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1, 1, 1});       // behind the camera
    gs.push_back({0.0f, 0.0f, 50.0f, 5.0f, 5.0f, 5.0f, 0.7f, 0.5f, 0.5f, 0.5f});  // on the far plane
    gs.push_back({0.0f, 0.0f, 50.01f, 5.0f, 5.0f, 5.0f, 1.0f, 1, 1, 1});      // beyond it
    gs.push_back({40.0f, 0.0f, 2.0f, 3.0f, 0.5f, 0.5f, 0.9f, 0, 1, 1});       // far right of the view
    gs.push_back({-9.0f, -7.0f, 3.0f, 1e3f, 1e-3f, 1e-3f, 0.9f, 1, 0.5f, 0}); // long needle from outside
    gs.push_back({0.5f, 0.5f, 6.0f, 0.4f, 0.3f, 0.2f, 0.0f, 1, 1, 1});        // opacity 0
    gs.push_back({-0.4f, 0.3f, 3.0f, 1e-7f, 1e-7f, 1e-7f, 1.0f, 1, 1, 1});    // far below a pixel
    for (int k = 0; k < 4; ++k)  // coincident: same depth, same place; index order decides
        gs.push_back({-0.3f, -0.3f, 3.5f, 0.3f, 0.2f, 0.1f, 0.5f, float(k == 0), float(k == 1), float(k == 2)});
    for (int k = 0; k < 40; ++k)  // a stack that saturates pixels (transmittance stop)
        gs.push_back({0.4f, -0.35f, 2.0f + 0.01f * float(k), 0.15f, 0.15f, 0.15f, 0.99f,
                      float(k % 3 == 0), float(k % 3 == 1), float(k % 3 == 2)});
    gs.push_back({0.2f, 0.4f, 2.5f, 0.2f, 0.05f, 0.1f, 0.8f, 0.2f, 0.9f, 0.4f, 10.0f, -3.0f, 4.0f, 7.0f});

    GaussianCloud c(gs.size(), 1);
    for (std::size_t i = 0; i < gs.size(); ++i) {
        const G& s = gs[i];
        c.means[3 * i] = s.x;
        c.means[3 * i + 1] = s.y;
        c.means[3 * i + 2] = s.z;
        c.scales[3 * i] = s.sx;
        c.scales[3 * i + 1] = s.sy;
        c.scales[3 * i + 2] = s.sz;
        set_rotation(c, i, s.qw, s.qx, s.qy, s.qz);
        c.opacities[i] = s.opacity;
        const float rgb[3] = {s.r, s.g, s.b};
        for (int a = 0; a < 3; ++a) {
            c.sh[12 * i + a] = float(avsplat::sh::color_to_dc(double(rgb[a])));
            c.sh[12 * i + 3 + 3 * a + a % 3] = 0.2f;  // some view dependence
        }
    }
    return c;
}

Camera extreme_camera() { return Camera(120.0, 110.0, 70.3, 44.8, 141, 90, Eigen::Matrix4d::Identity(), 0.1, 50.0); }

/// Stiff Gaussians for extreme_camera: scale ratios of 1e6 (needles, pancakes) and scales of
/// 1e-8 and 1e4, 20 of each with random rotations, opacities 1 or random.
GaussianCloud stiff_scene() {
    const float scales[][3] = {{1, 1e-6f, 1e-6f}, {1e-6f, 1, 1e-6f}, {1, 1, 1e-6f}, {1e-6f, 1, 1},
                               {1e-8f, 1e-8f, 1e-8f}, {1e4f, 1e4f, 1e4f}, {1e4f, 1e-8f, 1}};
    std::mt19937 rng(17);
    std::normal_distribution<float> g(0.0f, 1.0f);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    GaussianCloud c(std::size(scales) * 20, 0);
    for (std::size_t i = 0; i < c.size(); ++i) {
        const float* s = scales[i / 20];
        const float mean[3] = {0.5f * g(rng), 0.5f * g(rng), 3.0f + 0.3f * g(rng)};
        for (int a = 0; a < 3; ++a) {
            c.means[3 * i + a] = mean[a];
            c.scales[3 * i + a] = s[a];
            c.sh[3 * i + a] = g(rng);
        }
        set_rotation(c, i, g(rng), g(rng), g(rng), g(rng));
        c.opacities[i] = i % 5 == 0 ? 1.0f : u(rng);
    }
    return c;
}

/// n faint Gaussians (opacity 0.004..0.02) all inside the first tile of extreme_camera's image:
/// a long tile list, many batches, late saturation.
GaussianCloud one_tile_scene(std::size_t n) {
    std::mt19937 rng(19);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    GaussianCloud c(n, 0);
    const Camera cam = extreme_camera();
    for (std::size_t i = 0; i < n; ++i) {
        const float z = 4.0f + 0.01f * u(rng);
        c.means[3 * i] = float((16.0 * u(rng) - cam.cx) / cam.fx) * z;
        c.means[3 * i + 1] = float((16.0 * u(rng) - cam.cy) / cam.fy) * z;
        c.means[3 * i + 2] = z;
        c.scales[3 * i] = 0.01f;
        c.scales[3 * i + 1] = 0.02f;
        c.scales[3 * i + 2] = 0.01f;
        c.opacities[i] = 0.004f + 0.016f * u(rng);
        for (int a = 0; a < 3; ++a) c.sh[3 * i + a] = float(avsplat::sh::color_to_dc(double(u(rng))));
    }
    return c;
}


/// Far from the origin with a camera next to it: camera-space means must be computed in double.
GaussianCloud shifted(GaussianCloud c, float offset) {
    for (std::size_t i = 0; i < c.size(); ++i)
        for (int a = 0; a < 3; ++a) c.means[3 * i + a] += offset;
    return c;
}

Camera shifted_camera(const Camera& cam, double offset) {
    Camera c = cam;
    const Eigen::Matrix3d R = cam.world_to_camera.topLeftCorner<3, 3>();
    c.world_to_camera.topRightCorner<3, 1>() -= R * Eigen::Vector3d::Constant(offset);
    return c;
}

// ---- the GPU frame, assembled on the host from the kernels' bodies -------------------------

/// Runs the CUDA pipeline's per-thread functions on the host in the order and with the data
/// flow of render_cuda.cu: project -> inclusive scan -> emit keys -> stable sort on
/// [0, sort_end_bit) -> tile ranges -> per tile, batches of kBlockPixels with early exit.
template <class T>
RenderResult emulate_gpu_frame(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& options) {
    const gpu::FramePlan plan = gpu::plan_frame(camera.width, camera.height);
    const gpu::ViewParams<T> view = gpu::view_params<T>(camera, options, cloud.sh_degree);
    const gpu::BlendParams<T> bp = gpu::blend_params<T>(options);
    const std::size_t n = cloud.size();
    const std::size_t k = std::size_t(cloud.sh_coeffs()) * 3;

    std::vector<gpu::SplatRecord<T>> records(n);
    std::vector<std::uint64_t> counts(n), ends(n);
    std::uint64_t visible = 0;
    for (std::size_t i = 0; i < n; ++i) {
        counts[i] = gpu::project_record(view, &cloud.means[3 * i], &cloud.scales[3 * i],
                                        &cloud.rotations[4 * i], cloud.opacities[i], &cloud.sh[k * i], records[i]);
        visible += counts[i] > 0;
    }
    std::uint64_t running = 0;
    for (std::size_t i = 0; i < n; ++i) ends[i] = running += counts[i];
    const std::uint64_t instances = running;
    gpu::check_tile_instances(instances);

    std::vector<std::uint64_t> keys(instances);
    std::vector<std::uint32_t> values(instances);
    for (std::size_t i = 0; i < n; ++i)
        if (counts[i]) {
            const std::uint64_t first = ends[i] - counts[i];
            gpu::write_tile_keys(records[i], std::uint32_t(i), plan.tiles_x, &keys[first], &values[first]);
        }
    // The radix sort only looks at bits [0, sort_end_bit): all other bits must be zero.
    for (const std::uint64_t key : keys) REQUIRE((plan.sort_end_bit >= 64 || (key >> plan.sort_end_bit) == 0));
    std::vector<std::uint32_t> order(instances);
    for (std::uint32_t j = 0; j < instances; ++j) order[j] = j;
    std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
    std::vector<std::uint64_t> sorted_keys(instances);
    std::vector<std::uint32_t> sorted_values(instances);
    for (std::uint32_t j = 0; j < instances; ++j) {
        sorted_keys[j] = keys[order[j]];
        sorted_values[j] = values[order[j]];
    }
    std::vector<std::uint32_t> starts(plan.tiles, 0), stops(plan.tiles, 0);
    for (std::uint32_t j = 0; j < instances; ++j)
        gpu::mark_tile_range(sorted_keys.data(), j, std::uint32_t(instances), starts.data(), stops.data());

    RenderResult out;
    out.width = plan.width;
    out.height = plan.height;
    out.color.assign(3 * plan.pixels, 0.0f);
    out.alpha.assign(plan.pixels, 0.0f);
    out.depth.assign(plan.pixels, 0.0f);
    out.contributors.assign(plan.pixels, 0);
    std::uint64_t blends = 0, contributions = 0;
    const int ts = tiling::kTileSize;
    for (int ty = 0; ty < plan.tiles_y; ++ty)
        for (int tx = 0; tx < plan.tiles_x; ++tx) {
            const std::uint32_t tile = std::uint32_t(ty * plan.tiles_x + tx);
            std::vector<gpu::PixelState<T>> px(gpu::kBlockPixels);
            for (int l = 0; l < gpu::kBlockPixels; ++l) {
                const int x = tx * ts + l % ts, y = ty * ts + l / ts;
                px[l] = gpu::pixel_start<T>(x < plan.width && y < plan.height);
            }
            for (std::uint32_t first = starts[tile]; first < stops[tile]; first += gpu::kBlockPixels) {
                int done = 0;
                for (const auto& p : px) done += p.done;
                if (done == gpu::kBlockPixels) break;
                const std::uint32_t m = std::min<std::uint32_t>(gpu::kBlockPixels, stops[tile] - first);
                for (int l = 0; l < gpu::kBlockPixels; ++l) {
                    const int x = tx * ts + l % ts, y = ty * ts + l / ts;
                    for (std::uint32_t j = 0; j < m && !px[l].done; ++j)
                        gpu::composite(px[l], records[sorted_values[first + j]], x, y, T(x) + T(0.5),
                                       T(y) + T(0.5), bp);
                }
            }
            for (int l = 0; l < gpu::kBlockPixels; ++l) {
                const int x = tx * ts + l % ts, y = ty * ts + l / ts;
                blends += px[l].evaluated;
                contributions += std::uint64_t(px[l].contributors);
                if (x >= plan.width || y >= plan.height) continue;
                const std::size_t pix = std::size_t(y) * plan.width + x;
                gpu::finish(px[l], bp, &out.color[3 * pix], out.alpha[pix], out.depth[pix]);
                out.contributors[pix] = px[l].contributors;
            }
        }
    out.stats.gaussians = n;
    out.stats.visible = visible;
    out.stats.tile_instances = instances;
    out.stats.blends = blends;
    out.stats.contributions = contributions;
    return out;
}

// ---- comparison ----------------------------------------------------------------------------

struct Difference {
    double color = 0, alpha = 0, depth_rel = 0;
    std::size_t contributor_pixels = 0;  ///< pixels whose contributor counts differ
    std::string first_contributor;       ///< the first of them, for the message
};

Difference compare(const RenderResult& a, const RenderResult& b) {
    REQUIRE(a.width == b.width);
    REQUIRE(a.height == b.height);
    REQUIRE(a.color.size() == b.color.size());
    Difference d;
    for (std::size_t i = 0; i < a.color.size(); ++i)
        d.color = std::max(d.color, double(std::abs(a.color[i] - b.color[i])));
    for (std::size_t i = 0; i < a.alpha.size(); ++i) {
        d.alpha = std::max(d.alpha, double(std::abs(a.alpha[i] - b.alpha[i])));
        const double scale = std::max(1.0, double(std::abs(b.depth[i])));
        d.depth_rel = std::max(d.depth_rel, double(std::abs(a.depth[i] - b.depth[i])) / scale);
        if (a.contributors[i] != b.contributors[i]) {
            if (d.contributor_pixels++ == 0) {
                std::ostringstream os;
                os << "pixel (" << i % a.width << ", " << i / a.width << "): " << a.contributors[i]
                   << " vs " << b.contributors[i];
                d.first_contributor = os.str();
            }
        }
    }
    return d;
}

/// The bar for a back end against the CPU renderer: colour and alpha within `tol`, depth within
/// `tol` relative, the same contributors at every pixel and the same counters.
void require_match(const RenderResult& got, const RenderResult& cpu, double tol) {
    const Difference d = compare(got, cpu);
    INFO("max |colour| " << d.color << ", max |alpha| " << d.alpha << ", max depth rel " << d.depth_rel
                         << ", contributor mismatches " << d.contributor_pixels << " " << d.first_contributor);
    CHECK(d.color <= tol);
    CHECK(d.alpha <= tol);
    CHECK(d.depth_rel <= tol);
    CHECK(d.contributor_pixels == 0);
    CHECK(got.stats.gaussians == cpu.stats.gaussians);
    CHECK(got.stats.visible == cpu.stats.visible);
    CHECK(got.stats.tile_instances == cpu.stats.tile_instances);
    CHECK(got.stats.blends == cpu.stats.blends);
    CHECK(got.stats.contributions == cpu.stats.contributions);
}

RenderOptions with(Precision precision, Backend backend = Backend::Cpu) {
    RenderOptions o;
    o.precision = precision;
    o.backend = backend;
    o.background = {0.1f, 0.2f, 0.3f};
    return o;
}

/// Options that exercise the non-default paths: antialiasing, a wider box, a high stop.
RenderOptions unusual(Precision precision, Backend backend = Backend::Cpu) {
    RenderOptions o = with(precision, backend);
    o.antialiased = true;
    o.extent_sigma = 3.5f;
    o.low_pass = 0.1f;
    o.transmittance_stop = 0.05f;
    o.alpha_threshold = 0.02f;
    return o;
}

std::string message_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const std::exception& e) {
        return e.what();
    }
    return "(no exception)";
}

bool starts_with(const std::string& s, const std::string& prefix) { return s.rfind(prefix, 0) == 0; }

#ifdef AVSPLAT_TEST_CUDA
constexpr bool kBuiltWithCuda = true;
#else
constexpr bool kBuiltWithCuda = false;
#endif

/// For the [gpu] tests: true when a device is there, else says so and the test passes.
bool have_gpu() {
    if (avsplat::cuda_device_count() > 0) return true;
    WARN("SKIPPED: no CUDA device" << (kBuiltWithCuda ? "" : " (avsplat built without CUDA)"));
    return false;
}

}  // namespace

// ================================ everywhere ================================================

TEST_CASE("plan_frame: tiles, pixels and sort bits follow tiling.h", "[render_cuda]") {
    const int sizes[][2] = {{1, 1}, {16, 16}, {17, 1}, {1, 17}, {157, 93}, {1280, 720}, {4096, 2160}, {70000, 3}};
    for (const auto& s : sizes) {
        const gpu::FramePlan p = gpu::plan_frame(s[0], s[1]);
        INFO(s[0] << " x " << s[1]);
        CHECK(p.tiles_x == tiling::tiles_along(s[0]));
        CHECK(p.tiles_y == tiling::tiles_along(s[1]));
        CHECK(p.tiles == std::uint32_t(p.tiles_x * p.tiles_y));
        CHECK(p.pixels == std::size_t(s[0]) * std::size_t(s[1]));
        // Every key of this frame fits the sorted bits, and no fewer bits would do.
        const std::uint64_t last = tiling::tile_depth_key(p.tiles - 1, std::numeric_limits<float>::max());
        CHECK((last >> p.sort_end_bit) == 0);
        if (p.tiles > 1) CHECK(((p.tiles - 1) >> (p.sort_end_bit - 33)) != 0);
        else CHECK(p.sort_end_bit == 32);
    }
    CHECK_THROWS_AS(gpu::plan_frame(0, 10), std::invalid_argument);
    CHECK_THROWS_AS(gpu::plan_frame(10, -1), std::invalid_argument);
    CHECK_THROWS_WITH(gpu::plan_frame(8, 16 * gpu::kMaxGridY + 1), Catch::Contains("tile rows"));
    CHECK_NOTHROW(gpu::plan_frame(8, 16 * gpu::kMaxGridY));
    CHECK(gpu::bit_width(0) == 0);
    CHECK(gpu::bit_width(1) == 1);
    CHECK(gpu::bit_width(0xffffffffu) == 32);
    CHECK(gpu::grid_blocks(0) == 0);
    CHECK(gpu::grid_blocks(1) == 1);
    CHECK(gpu::grid_blocks(256) == 1);
    CHECK(gpu::grid_blocks(257) == 2);
    CHECK(gpu::grid_blocks(std::uint64_t(1) << 32) == (1u << 24));
}

TEST_CASE("check_tile_instances and frame_sizes: the limit of one sort, the buffers of a frame", "[render_cuda]") {
    CHECK_NOTHROW(gpu::check_tile_instances(0));
    CHECK_NOTHROW(gpu::check_tile_instances(gpu::kMaxTileInstances));
    CHECK_THROWS_AS(gpu::check_tile_instances(gpu::kMaxTileInstances + 1), avsplat::DeviceError);
    // The buffers of a 1280 x 720 frame of 10 Gaussians of degree 3: per Gaussian 59 input
    // floats, one record, count and offset; one range per tile (80 x 45); images per pixel.
    const gpu::FramePlan p = gpu::plan_frame(1280, 720);
    const gpu::FrameSizes s = gpu::frame_sizes(p, 10, 3);
    CHECK(s.gaussians == 10);
    CHECK(s.input_floats == 10 * (3 + 3 + 4 + 1 + 48));
    CHECK(s.tiles == std::uint64_t(tiling::tiles_along(1280) * tiling::tiles_along(720)));
    CHECK(s.tiles == 3600);
    CHECK(s.pixels == 921600);
    CHECK(gpu::sh_floats(0) == 3);
    CHECK(gpu::sh_floats(3) == 48);
    // 100 instances: keys (8 bytes) and values (4), both double-buffered.
    const std::uint64_t expected = 10 * (56 + 16) + 2 * 100 * 12 + 2 * 3600 * 4 + 921600 * 24;
    CHECK(s.bytes(100, 56, false) == expected);
    CHECK(s.bytes(100, 56, true) == expected + 10 * 59 * 4);
    CHECK(sizeof(gpu::SplatRecord<float>) == 56);
}

TEST_CASE("key packing: one global sort by tile_depth_key gives each tile the CPU's order", "[render_cuda]") {
    std::mt19937 rng(11);
    std::uniform_int_distribution<std::uint32_t> tile(0, 40);
    std::uniform_int_distribution<int> pick(0, 9);
    const float depths[] = {-3.5f, -0.0f, 0.0f, 1e-30f, 0.25f, 0.25f, 1.0f, 7.5f, 1e30f, 0.2500001f};
    struct Item {
        std::uint32_t tile, index;
        float depth;
    };
    std::vector<Item> items;
    for (std::uint32_t i = 0; i < 3000; ++i) items.push_back({tile(rng), i, depths[pick(rng)]});
    // GPU: keys in index order, stable sort by key.
    std::vector<Item> gpu_order = items;
    std::stable_sort(gpu_order.begin(), gpu_order.end(), [](const Item& a, const Item& b) {
        return tiling::tile_depth_key(a.tile, a.depth) < tiling::tile_depth_key(b.tile, b.depth);
    });
    // CPU: per tile, sort by depth_index_key.
    std::vector<Item> cpu_order = items;
    std::sort(cpu_order.begin(), cpu_order.end(), [](const Item& a, const Item& b) {
        if (a.tile != b.tile) return a.tile < b.tile;
        return tiling::depth_index_key(a.depth, a.index) < tiling::depth_index_key(b.depth, b.index);
    });
    for (std::size_t j = 0; j < items.size(); ++j) {
        INFO("position " << j);
        REQUIRE(gpu_order[j].index == cpu_order[j].index);
        CHECK(gpu::key_tile(tiling::tile_depth_key(gpu_order[j].tile, gpu_order[j].depth)) == gpu_order[j].tile);
    }
    // Depth order itself: increasing floats give increasing keys within a tile.
    for (std::size_t a = 0; a < std::size(depths); ++a)
        for (std::size_t b = 0; b < std::size(depths); ++b)
            if (depths[a] < depths[b])
                CHECK(tiling::tile_depth_key(5, depths[a]) < tiling::tile_depth_key(5, depths[b]));
    CHECK(tiling::tile_depth_key(4, 1e30f) < tiling::tile_depth_key(5, -1e30f));
}

TEST_CASE("write_tile_keys and mark_tile_range list every splat in exactly the tiles its box meets", "[render_cuda]") {
    const gpu::FramePlan plan = gpu::plan_frame(100, 70);  // 7 x 5 tiles, the last ones partial
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> ux(0, 99), uy(0, 69);
    std::uniform_real_distribution<float> depth(0.5f, 2.0f);
    const int n = 300;
    std::vector<gpu::SplatRecord<float>> recs(n);
    std::vector<std::uint64_t> keys;
    std::vector<std::uint32_t> values;
    for (int i = 0; i < n; ++i) {
        gpu::SplatRecord<float>& r = recs[i];
        const int x0 = ux(rng), x1 = ux(rng), y0 = uy(rng), y1 = uy(rng);
        r.x_min = std::min(x0, x1);
        r.x_max = std::max(x0, x1);
        r.y_min = std::min(y0, y1);
        r.y_max = std::max(y0, y1);
        r.depth = i % 7 == 0 ? 1.0f : depth(rng);  // some ties
        const int count = tiling::tile_count(tiling::tile_rect(r.x_min, r.x_max, r.y_min, r.y_max));
        const std::size_t first = keys.size();
        keys.resize(first + count);
        values.resize(first + count);
        gpu::write_tile_keys(r, std::uint32_t(i), plan.tiles_x, &keys[first], &values[first]);
    }
    std::vector<std::size_t> order(keys.size());
    for (std::size_t j = 0; j < order.size(); ++j) order[j] = j;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return keys[a] < keys[b]; });
    std::vector<std::uint64_t> sk(keys.size());
    for (std::size_t j = 0; j < order.size(); ++j) sk[j] = keys[order[j]];
    std::vector<std::uint32_t> starts(plan.tiles, 0), ends(plan.tiles, 0);
    for (std::uint32_t j = 0; j < sk.size(); ++j)
        gpu::mark_tile_range(sk.data(), j, std::uint32_t(sk.size()), starts.data(), ends.data());

    for (int ty = 0; ty < plan.tiles_y; ++ty)
        for (int tx = 0; tx < plan.tiles_x; ++tx) {
            // Brute force: the splats whose box overlaps the tile's pixels, by (depth, index).
            std::vector<std::pair<float, int>> expected;
            for (int i = 0; i < n; ++i) {
                const auto& r = recs[i];
                const bool overlap = r.x_max >= 16 * tx && r.x_min < 16 * tx + 16 && r.y_max >= 16 * ty &&
                                     r.y_min < 16 * ty + 16;
                if (overlap) expected.push_back({r.depth, i});
            }
            std::sort(expected.begin(), expected.end());
            const std::uint32_t tile = std::uint32_t(ty * plan.tiles_x + tx);
            INFO("tile " << tx << ", " << ty);
            REQUIRE(ends[tile] - starts[tile] == expected.size());
            for (std::size_t j = 0; j < expected.size(); ++j)
                CHECK(int(values[order[starts[tile] + j]]) == expected[j].second);
        }
}

TEST_CASE("composite: hand-computed steps, box, threshold and saturation", "[render_cuda]") {
    gpu::BlendParams<double> bp{0.1, 0.5, {1.0, 1.0, 1.0}};
    gpu::SplatRecord<double> s{};
    s.mean_x = 3.5;
    s.mean_y = 2.5;
    s.conic_a = 1.0;
    s.conic_b = 0.0;
    s.conic_c = 1.0;
    s.opacity = 0.3;
    s.rgb[0] = 1.0;
    s.rgb[1] = 0.5;
    s.rgb[2] = 0.0;
    s.depth = 4.0;
    s.x_min = 2;
    s.x_max = 4;
    s.y_min = 1;
    s.y_max = 3;
    auto p = gpu::pixel_start<double>(true);
    gpu::composite(p, s, 3, 2, 3.5, 2.5, bp);  // at the mean: power 0, alpha = opacity
    CHECK(p.transmittance == Approx(0.7));
    CHECK(p.rgb[0] == Approx(0.3));
    CHECK(p.rgb[1] == Approx(0.15));
    CHECK(p.depth == Approx(1.2));
    CHECK(p.contributors == 1);
    CHECK(p.evaluated == 1);
    // One pixel to the right: power -0.5, alpha 0.3 e^-0.5 = 0.182 (above 0.1).
    auto q = gpu::pixel_start<double>(true);
    gpu::composite(q, s, 4, 2, 4.5, 2.5, bp);
    CHECK(q.transmittance == Approx(1.0 - 0.3 * std::exp(-0.5)));
    // Two to the right: outside the box [2, 4]; untouched and not evaluated.
    auto r = gpu::pixel_start<double>(true);
    gpu::composite(r, s, 5, 2, 5.5, 2.5, bp);
    CHECK(r.transmittance == 1.0);
    CHECK(r.evaluated == 0);
    // In the box of a narrower splat, alpha 0.3 e^-2 = 0.04 < 0.1: evaluated, skipped.
    gpu::SplatRecord<double> narrow = s;
    narrow.conic_a = narrow.conic_c = 2.0;
    gpu::composite(r, narrow, 4, 3, 4.5, 3.5, bp);
    CHECK(r.transmittance == 1.0);
    CHECK(r.evaluated == 1);
    CHECK(r.contributors == 0);
    // Saturation: 0.7 (1 - 0.6) = 0.28 < 0.5, so the second splat is not blended and the pixel
    // is done; a third splat is not even looked at.
    gpu::SplatRecord<double> strong = s;
    strong.opacity = 0.6;
    gpu::composite(p, strong, 3, 2, 3.5, 2.5, bp);
    CHECK(p.done);
    CHECK(p.contributors == 1);
    CHECK(p.evaluated == 2);
    CHECK(p.transmittance == Approx(0.7));
    gpu::composite(p, strong, 3, 2, 3.5, 2.5, bp);
    CHECK(p.evaluated == 2);
    float rgb[3], alpha, depth;
    gpu::finish(p, bp, rgb, alpha, depth);
    CHECK(rgb[0] == Approx(0.3 + 0.7));
    CHECK(rgb[2] == Approx(0.7));
    CHECK(alpha == Approx(0.3));
    CHECK(depth == Approx(4.0));
    // A thread without a pixel starts done and never changes.
    auto none = gpu::pixel_start<float>(false);
    CHECK(none.done);
}

TEST_CASE("project_record: degree-0 colour and culling", "[render_cuda]") {
    GaussianCloud c(3, 0);
    for (int a = 0; a < 3; ++a) c.scales[a] = c.scales[3 + a] = c.scales[6 + a] = 0.1f;
    c.means[2] = 2.0f;    // in front
    c.means[5] = -1.0f;   // behind the camera
    c.means[8] = 2.0f;
    c.opacities[2] = 0.001f;  // below the alpha threshold
    c.sh[0] = 1.0f;
    c.sh[1] = -3.0f;  // clamped at 0
    c.sh[2] = 10.0f;  // not clamped at 1
    const Camera cam(100, 100, 32, 32, 64, 64);
    const auto v = gpu::view_params<float>(cam, RenderOptions{}, 0);
    gpu::SplatRecord<float> rec;
    // Box: 3 sigma of sqrt((100 * 0.1 / 2)^2 + 0.3) pixels around (32, 32): pixels 17..46,
    // tiles 1..2 along each axis.
    REQUIRE(gpu::project_record(v, &c.means[0], &c.scales[0], &c.rotations[0], c.opacities[0], &c.sh[0], rec) == 4);
    CHECK(rec.rgb[0] == Approx(0.5 + avsplat::sh::kC0));
    CHECK(rec.rgb[1] == 0.0f);
    CHECK(rec.rgb[2] == Approx(0.5 + 10 * avsplat::sh::kC0));
    CHECK(rec.mean_x == Approx(32.0f));
    CHECK(rec.depth == 2.0f);
    const double radius = 3.0 * std::sqrt(25.0 + 0.3);
    CHECK(rec.x_min == int(std::ceil(32.0 - radius - 0.5)));
    CHECK(rec.x_max == int(std::floor(32.0 + radius - 0.5)));
    CHECK(gpu::project_record(v, &c.means[3], &c.scales[3], &c.rotations[4], c.opacities[1], &c.sh[3], rec) == 0);
    CHECK(gpu::project_record(v, &c.means[6], &c.scales[6], &c.rotations[8], c.opacities[2], &c.sh[6], rec) == 0);
}

TEST_CASE("check_gaussian: the checks and messages of validate()", "[render_cuda]") {
    struct Case {
        const char* name;
        std::function<void(GaussianCloud&)> corrupt;
    };
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const std::vector<Case> cases = {
        {"NaN mean", [&](GaussianCloud& c) { c.means[3 * 3 + 1] = nan; }},
        {"Inf scale", [&](GaussianCloud& c) { c.scales[3 * 3] = inf; }},
        {"NaN rotation", [&](GaussianCloud& c) { c.rotations[4 * 3 + 2] = nan; }},
        {"Inf opacity", [&](GaussianCloud& c) { c.opacities[3] = -inf; }},
        {"NaN sh", [&](GaussianCloud& c) { c.sh[3 * 48 + 47] = nan; }},
        {"negative scale", [&](GaussianCloud& c) { c.scales[3 * 3 + 2] = -1e-9f; }},
        {"zero quaternion", [&](GaussianCloud& c) { for (int a = 0; a < 4; ++a) c.rotations[12 + a] = 0.0f; }},
        {"opacity above 1", [&](GaussianCloud& c) { c.opacities[3] = 1.0001f; }},
        {"opacity below 0", [&](GaussianCloud& c) { c.opacities[3] = -0.5f; }},
        {"two problems: the first field wins", [&](GaussianCloud& c) { c.opacities[3] = 2.0f; c.sh[3 * 48] = nan; }},
        {"two Gaussians: the first index wins", [&](GaussianCloud& c) { c.opacities[3] = 2.0f; c.means[4 * 3] = nan; }},
    };
    for (const Case& k : cases) {
        INFO(k.name);
        GaussianCloud c = random_scene(6, 3, 1);
        k.corrupt(c);
        const std::string host = message_of([&] { avsplat::validate(c); });
        REQUIRE(starts_with(host, "GaussianCloud."));
        std::string device = "(valid)";
        for (std::size_t i = 0; i < c.size(); ++i) {
            gpu::Field field = gpu::Field::Means;
            const gpu::Invalid why = gpu::check_gaussian(&c.means[3 * i], &c.scales[3 * i], &c.rotations[4 * i],
                                                         c.opacities[i], &c.sh[48 * i], 48, field);
            if (why != gpu::Invalid::None) {
                device = gpu::invalid_message(i, field, why);
                break;
            }
        }
        CHECK(device == "DeviceGaussians." + host.substr(std::string("GaussianCloud.").size()));
    }
    const GaussianCloud ok = random_scene(6, 3, 1);
    gpu::Field field = gpu::Field::Means;
    for (std::size_t i = 0; i < ok.size(); ++i)
        CHECK(gpu::check_gaussian(&ok.means[3 * i], &ok.scales[3 * i], &ok.rotations[4 * i], ok.opacities[i],
                                  &ok.sh[48 * i], 48, field) == gpu::Invalid::None);
}

TEST_CASE("the GPU pipeline run on the host matches the CPU renderer", "[render_cuda]") {
    struct Scene {
        const char* name;
        GaussianCloud cloud;
        Camera camera;
    };
    const std::vector<Scene> scenes = {
        {"random degree 3", random_scene(2500, 3, 3), random_camera()},
        {"random degree 2", random_scene(800, 2, 4), random_camera(64, 64)},
        {"random degree 0, 1280 x 8", random_scene(600, 0, 5), random_camera(1280, 8)},
        {"extreme", extreme_scene(), extreme_camera()},
        {"stiff", stiff_scene(), extreme_camera()},
        {"5000 in one tile", one_tile_scene(5000), extreme_camera()},
        {"far from the origin", shifted(random_scene(500, 1, 6), 1e6f), shifted_camera(random_camera(), 1e6)},
        {"empty", GaussianCloud(0, 3), random_camera(40, 20)},
    };
    for (const Scene& s : scenes) {
        for (const RenderOptions& o : {with(Precision::Float32), with(Precision::Float64),
                                       unusual(Precision::Float32), unusual(Precision::Float64)}) {
            INFO(s.name << (o.precision == Precision::Float64 ? ", float64" : ", float32")
                        << (o.antialiased ? ", unusual options" : ""));
            const RenderResult cpu = avsplat::render(s.cloud, s.camera, o);
            const RenderResult emu = o.precision == Precision::Float64
                                         ? emulate_gpu_frame<double>(s.cloud, s.camera, o)
                                         : emulate_gpu_frame<float>(s.cloud, s.camera, o);
            // Same functions, same compiler: the GPU's bar (1e-4) with a large margin.
            require_match(emu, cpu, 1e-6);
        }
    }
}

TEST_CASE("the scenes of these tests exercise what they are meant to", "[render_cuda]") {
    // Without these the comparisons above could pass on scenes that test nothing.
    const RenderResult r = avsplat::render(random_scene(2500, 3, 3), random_camera(), with(Precision::Float32));
    CHECK(r.stats.visible > 500);
    CHECK(r.stats.visible < 2500);  // some culled
    CHECK(r.stats.tile_instances > r.stats.visible);
    const RenderResult e = avsplat::render(extreme_scene(), extreme_camera(), with(Precision::Float32));
    const GaussianCloud ex = extreme_scene();
    CHECK(e.stats.visible < ex.size());
    CHECK(e.stats.visible > ex.size() / 2);
    // The stack of 40 splats of opacity 0.99 reaches the transmittance stop after a few.
    int stopped = 0;
    for (std::size_t i = 0; i < e.alpha.size(); ++i) stopped += e.alpha[i] > 0.999f && e.contributors[i] <= 5;
    CHECK(stopped > 10);
    CHECK(*std::min_element(e.alpha.begin(), e.alpha.end()) > 0.0f);  // the huge splat covers all
    const RenderResult t = avsplat::render(one_tile_scene(5000), extreme_camera(), with(Precision::Float32));
    CHECK(t.stats.visible == 5000);
    CHECK(t.stats.tile_instances >= 5000);
    CHECK(t.alpha[5 * 141 + 5] > 0.3f);
    CHECK(t.alpha[60 * 141 + 100] == 0.0f);
}

TEST_CASE("backend Cuda without a CUDA renderer or device is a clear DeviceError", "[render_cuda]") {
    CHECK_NOTHROW(avsplat::cuda_device_count());
    if (avsplat::cuda_device_count() > 0) {
        SUCCEED("a CUDA device is present: the [gpu] tests cover backend Cuda");
        return;
    }
    const GaussianCloud cloud = random_scene(10, 1, 2);
    const std::string msg = message_of([&] {
        avsplat::render(cloud, random_camera(), with(Precision::Float32, Backend::Cuda));
    });
    INFO(msg);
    if (kBuiltWithCuda) CHECK(starts_with(msg, "no CUDA device: "));
    else CHECK_THAT(msg, Catch::Contains("built without the CUDA renderer"));
    CHECK_THROWS_AS(avsplat::render(cloud, random_camera(), with(Precision::Float32, Backend::Cuda)),
                    avsplat::DeviceError);

    avsplat::DeviceGaussians d;  // empty: reaches the device check
    CHECK_THROWS_AS(avsplat::render(d, random_camera(), with(Precision::Float32, Backend::Cuda)), avsplat::DeviceError);
}

TEST_CASE("DeviceGaussianCloud without a CUDA renderer or device is a clear DeviceError", "[render_cuda]") {
    if (avsplat::cuda_device_count() > 0) {
        SUCCEED("a CUDA device is present: the [gpu] tests use DeviceGaussianCloud");
        return;
    }
    const GaussianCloud cloud = random_scene(10, 1, 2);
    const std::string msg = message_of([&] { avsplat::DeviceGaussianCloud d(cloud); });
    INFO(msg);
    if (kBuiltWithCuda) CHECK(starts_with(msg, "no CUDA device: "));
    else CHECK_THAT(msg, Catch::Contains("built without the CUDA renderer"));
    CHECK_THROWS_AS(avsplat::DeviceGaussianCloud(cloud), avsplat::DeviceError);
}

TEST_CASE("render(DeviceGaussians): argument checks before any device work", "[render_cuda]") {
    avsplat::DeviceGaussians d;
    CHECK_THROWS_WITH(avsplat::render(d, random_camera(), with(Precision::Float32, Backend::Cpu)),
                      Catch::Contains("RenderOptions.backend"));
    RenderOptions bad = with(Precision::Float32, Backend::Cuda);
    bad.alpha_threshold = 0.0f;
    CHECK_THROWS_WITH(avsplat::render(d, random_camera(), bad), Catch::Contains("RenderOptions.alpha_threshold"));
    Camera cam = random_camera();
    cam.fx = -1;
    CHECK_THROWS_AS(avsplat::render(d, cam, with(Precision::Float32, Backend::Cuda)), std::invalid_argument);
    d.sh_degree = 4;
    CHECK_THROWS_WITH(avsplat::render(d, random_camera(), with(Precision::Float32, Backend::Cuda)),
                      Catch::Contains("DeviceGaussians.sh_degree"));
}

// ================================ with a GPU ================================================

TEST_CASE("CUDA matches the CPU renderer on the random and extreme scenes", "[gpu]") {
    if (!have_gpu()) return;
    struct Scene {
        const char* name;
        GaussianCloud cloud;
        Camera camera;
    };
    const std::vector<Scene> scenes = {
        {"random degree 3", random_scene(20000, 3, 13), random_camera(333, 211)},
        {"random degree 1", random_scene(5000, 1, 14), random_camera()},
        {"extreme", extreme_scene(), extreme_camera()},
        {"stiff", stiff_scene(), extreme_camera()},
        {"50000 in one tile", one_tile_scene(50000), extreme_camera()},
        {"far from the origin", shifted(random_scene(3000, 2, 15), 1e6f), shifted_camera(random_camera(), 1e6)},
        {"empty", GaussianCloud(0, 0), random_camera(40, 20)},
    };
    for (const Scene& s : scenes) {
        for (const Precision p : {Precision::Float32, Precision::Float64}) {
            for (const bool odd : {false, true}) {
                INFO(s.name << (p == Precision::Float64 ? ", float64" : ", float32") << (odd ? ", unusual options" : ""));
                const RenderResult cpu = avsplat::render(s.cloud, s.camera, odd ? unusual(p) : with(p));
                const RenderResult cuda = avsplat::render(s.cloud, s.camera, odd ? unusual(p, Backend::Cuda) : with(p, Backend::Cuda));
                require_match(cuda, cpu, 1e-4);
            }
        }
    }
}

#ifdef AVSPLAT_TEST_CUDA

TEST_CASE("CUDA: device-pointer inputs give the host-input images", "[gpu]") {
    if (!have_gpu()) return;
    const GaussianCloud cloud = random_scene(8000, 3, 21);
    const avsplat::DeviceGaussianCloud dev(cloud);
    for (const Precision p : {Precision::Float32, Precision::Float64}) {
        const RenderResult from_host = avsplat::render(cloud, random_camera(), with(p, Backend::Cuda));
        const RenderResult from_device = avsplat::render(dev.view(), random_camera(), with(p, Backend::Cuda));
        CHECK(from_device.color == from_host.color);
        CHECK(from_device.alpha == from_host.alpha);
        CHECK(from_device.depth == from_host.depth);
        CHECK(from_device.contributors == from_host.contributors);
        CHECK(from_device.stats.blends == from_host.stats.blends);
        require_match(from_device, avsplat::render(cloud, random_camera(), with(p)), 1e-4);
    }
}

TEST_CASE("CUDA: device inputs are validated on the device, host memory is refused", "[gpu]") {
    if (!have_gpu()) return;
    GaussianCloud cloud = random_scene(5000, 2, 22);
    cloud.scales[3 * 4321 + 1] = -1.0f;
    cloud.opacities[4400] = 3.0f;
    {
        const avsplat::DeviceGaussianCloud dev(cloud);
        CHECK_THROWS_WITH(avsplat::render(dev.view(), random_camera(), with(Precision::Float32, Backend::Cuda)),
                          "DeviceGaussians.scales[4321]: negative scale");
    }
    cloud.scales[3 * 4321 + 1] = 1.0f;
    cloud.sh[27 * 77 + 5] = std::numeric_limits<float>::quiet_NaN();
    {
        const avsplat::DeviceGaussianCloud dev(cloud);
        CHECK_THROWS_WITH(avsplat::render(dev.view(), random_camera(), with(Precision::Float32, Backend::Cuda)),
                          "DeviceGaussians.sh[77]: NaN or Inf");
    }
    avsplat::DeviceGaussians host = gpu::cloud_arrays(cloud);  // host pointers
    CHECK_THROWS_WITH(avsplat::render(host, random_camera(), with(Precision::Float32, Backend::Cuda)),
                      Catch::Contains("DeviceGaussians.means: not device memory"));
    host.means = nullptr;
    CHECK_THROWS_WITH(avsplat::render(host, random_camera(), with(Precision::Float32, Backend::Cuda)),
                      Catch::Contains("DeviceGaussians.means: null pointer"));
}

#endif  // AVSPLAT_TEST_CUDA
