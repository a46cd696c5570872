// Splat rendering: the standard 3DGS forward pass (Kerbl et al. 2023) with gsplat's
// conventions, so that images are comparable with gsplat and the INRIA code.
//
// Pipeline (the rules themselves are documented where the shared code lives):
//   projection  projection.h: world -> camera, EWA 2D covariance + low-pass, antialiasing
//               compensation, conic, k-sigma box (the radius rule), culling by depth range,
//               degenerate covariance, opacity below the alpha threshold and box outside the image;
//   colour      sh.h: SH of degree 0..3 in the direction from the camera centre to the mean,
//               + 0.5, clamped at 0 (not at 1), once per Gaussian (as 3DGS);
//   binning     tiling.h: 16 x 16 tiles, each tile's splats ordered by view depth, ties by index;
//   blending    blend.h: front-to-back compositing with alpha = min(0.99, o exp(power)),
//               skip alpha < 1/255, stop at transmittance < 1e-4, background behind.
// A splat only ever touches the pixels whose centre lies in its k-sigma box, so the image does
// not depend on the tiling.
//
// Outputs, all row-major with H = camera.height rows and W = camera.width columns:
//   color         H x W x 3   sum(w_i rgb_i) + T background
//   alpha         H x W       1 - T (accumulated opacity)
//   depth         H x W       expected depth sum(w_i z_i) / alpha, z the camera-space z of the
//                             mean (gsplat "ED"); 0 where alpha is 0
//   contributors  H x W       number of splats blended into the pixel
// where w_i = alpha_i T_i is the weight of splat i and T the final transmittance.
//
// Only when RenderOptions::gaussian_contributions asks (the colour-only path computes nothing
// of it), per Gaussian i, N = cloud.size() values each:
//   contribution_max  N        max over the pixels p of c_i(p)
//   contribution_sum  N        sum over the pixels p of c_i(p) (per-tile partial sums added in
//                              double, tile by tile in a fixed order: thread-count independent)
// with c_i(p) = alpha_i(p) T_i(p) wherever the splat takes part in the compositing of pixel p:
// its weight w_i in the composite when it is blended, and, for the one splat at which a pixel
// stops (T (1 - alpha) < transmittance_stop: not blended, as in 3DGS, but it ends the pixel),
// the weight it would have had. Elsewhere (culled, alpha below alpha_threshold, pixel already
// stopped, outside its box) c_i(p) = 0. So c_i(p) > 0 exactly where removing Gaussian i could
// change pixel p: a Gaussian with contribution_max == 0 can be removed without changing any bit
// of this image (reduce/prune.h builds on this).
//
// The CPU back end runs float32 (fast path) or float64 (reference) from the same templated
// source, in parallel over tiles with OpenMP; each tile is independent, so the result does not
// depend on the number of threads. Camera-space means are computed in double in both precisions
// (so that world coordinates of 1e6 with a nearby camera do not lose the splat's position).
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/core/precision.h"

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace avsplat {

/// Where a render runs.
enum class Backend { Cpu, Cuda };

// Precision (float32 fast path / float64 reference) is defined in precision.h.

struct RenderOptions {
    Backend backend = Backend::Cpu;
    Precision precision = Precision::Float32;
    /// RGB behind the splats (any finite values).
    std::array<float, 3> background{0.0f, 0.0f, 0.0f};
    /// Multiply each opacity by the low-pass compensation (Mip-Splatting, gsplat "antialiased").
    bool antialiased = false;
    /// Added to the 2D covariance diagonal, pixels^2; >= 0 (3DGS: 0.3).
    float low_pass = 0.3f;
    /// Splats below this alpha are skipped at a pixel; in (0, 1) (3DGS: 1/255).
    float alpha_threshold = 1.0f / 255.0f;
    /// A pixel stops when its transmittance would fall below this; in (0, 1) (3DGS: 1e-4).
    float transmittance_stop = 1e-4f;
    /// k of the k-sigma box that bounds a splat's footprint; > 0 (3DGS: 3).
    float extent_sigma = 3.0f;
    /// Compute RenderResult::contribution_max and contribution_sum (header comment). CPU back end
    /// only: Backend::Cuda throws avsplat::DeviceError when this is set.
    bool gaussian_contributions = false;
};

/// Counters and timings of one render.
struct RenderStats {
    std::size_t gaussians = 0;       ///< Gaussians in the cloud
    std::size_t visible = 0;         ///< Gaussians that survived culling
    std::size_t tile_instances = 0;  ///< (splat, tile) pairs in the tile lists
    /// Gaussian-pixel pairs evaluated: pixel centre in the splat's box and pixel not yet
    /// saturated (each costs one exp and one compositing step).
    std::uint64_t blends = 0;
    std::uint64_t contributions = 0;  ///< sum of `contributors` over the image
    int threads = 1;                  ///< OpenMP threads used
    double seconds_projection = 0.0;  ///< projection, culling and SH colour
    double seconds_sorting = 0.0;     ///< tile binning and per-tile depth sort
    double seconds_blending = 0.0;    ///< compositing and writing the images
    double seconds_total = 0.0;       ///< the whole call, input checks included
    /// One line, e.g. "visible 1000/1200, 5000 tile instances, 1.2e6 blends, 3.1 ms".
    std::string summary() const;
};

/// The images of one render (shapes in the header comment) and its statistics.
struct RenderResult {
    int width = 0;
    int height = 0;
    std::vector<float> color;
    std::vector<float> alpha;
    std::vector<float> depth;
    std::vector<std::int32_t> contributors;
    /// True when RenderOptions::gaussian_contributions asked for the two arrays below.
    bool has_gaussian_contributions = false;
    /// N = cloud.size() values each when has_gaussian_contributions, else empty (header comment).
    std::vector<float> contribution_max;
    std::vector<float> contribution_sum;
    RenderStats stats;
};

/// Memory that CPU renders reuse from one call to the next: the per-Gaussian records and sort
/// keys, the depth-sorted records and their tile rectangles, the tile lists and their offsets
/// (about 170 bytes per Gaussian plus 4 per tile instance, and an eighth more as headroom; with
/// recycled images, 240 MB for 1M Gaussians of the benchmark at 1280 x 720). Without a
/// workspace every render() allocates these afresh and the kernel clears each new page, which on
/// some machines costs as much as the sorting itself; rendering many views of a cloud with one
/// workspace skips that. The images of a RenderResult belong to the result; give them back with
/// recycle() when a result is done with, and the next render reuses their memory too.
///
/// A workspace only ever grows (to the largest frame rendered with it) until release() or its
/// destruction; it holds no results, so the images never depend on what it was used for before.
/// One render at a time: a render() given a workspace that another render() is using (another
/// thread) throws std::logic_error rather than race. Ignored by Backend::Cuda. Movable, not
/// copyable.
class RenderWorkspace {
public:
    RenderWorkspace();
    ~RenderWorkspace();
    RenderWorkspace(RenderWorkspace&&) noexcept;
    RenderWorkspace& operator=(RenderWorkspace&&) noexcept;
    RenderWorkspace(const RenderWorkspace&) = delete;
    RenderWorkspace& operator=(const RenderWorkspace&) = delete;

    /// Bytes held now.
    std::size_t bytes() const;
    /// Frees all memory held (the workspace stays usable). Throws std::logic_error while a render
    /// (on another thread) uses the workspace.
    void release();
    /// Takes the images of a result the caller no longer needs (color, alpha, depth,
    /// contributors; the rest of it is dropped), so that the next render with this workspace
    /// writes its images into that memory instead of fresh pages. Every pixel is written by
    /// each render, so nothing of the old images shows. Does nothing while a render uses the
    /// workspace.
    void recycle(RenderResult&& result);

    struct Buffers;  ///< internal (lib/src/render/cpu/render_workspace.h)
    /// Internal: the buffers, for the renderer.
    Buffers& buffers();

private:
    std::unique_ptr<Buffers> buffers_;
};

/// Renders `cloud` from `camera` with options.backend.
/// Throws std::invalid_argument for an invalid cloud (validate(), naming the field and index),
/// camera (Camera::validate) or option (naming it), or a cloud of 2^32 Gaussians or more;
/// avsplat::DeviceError from Backend::Cuda when avsplat was built without CUDA, no device is
/// usable or a CUDA call fails (render_cuda.h), or when options.gaussian_contributions is set.
RenderResult render(const GaussianCloud& cloud, const Camera& camera,
                    const RenderOptions& options = {});

/// render() with `workspace`'s memory for the CPU back end's scratch buffers (RenderWorkspace):
/// the same image bit for bit, the same errors, plus std::logic_error when the workspace is in
/// use by another render at the same time.
RenderResult render(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& options,
                    RenderWorkspace& workspace);

}  // namespace avsplat
