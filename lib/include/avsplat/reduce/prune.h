// prune: leave out the Gaussians that cannot change an image.
//
// A Gaussian is removed, and counted under the first reason that applies, when it is
//   degenerate      invalid by the one validity rule of validate()/sanitize() (a non-finite
//                   field, a negative scale, a zero quaternion, an opacity outside [0, 1]);
//                   the renderer refuses such a cloud, so nothing is lost by dropping them;
//   low_opacity     opacity < min_opacity;
//   invisible       (only when cameras are given) its contribution c_i(p) (render.h: alpha T
//                   where it takes part in a pixel's compositing) is, at every pixel p of every
//                   camera, 0 (min_contribution unset, the default: the renderer's alpha
//                   threshold and transmittance rules leave it out everywhere) or below
//                   min_contribution (when set).
// The kept Gaussians keep their order, so renders keep their (depth, index) order.
//
// Guarantees, for a valid input cloud, rendered from the given cameras with params.render (the
// options the contributions were measured with; CPU back end):
//   - min_opacity <= render.alpha_threshold and min_contribution unset (the defaults): every
//     removed Gaussian leaves every pixel's compositing untouched (a splat skipped or never
//     reached does not change the state of the pixel), so the pruned cloud renders the same
//     images, bit for bit. Gaussians with opacity < alpha_threshold are never drawn from any
//     camera, so pruning without cameras changes no image at all.
//   - otherwise (min_contribution = c > 0, or min_opacity above the threshold): with S the
//     removed set, D the spread of colours (per channel, max(largest colour of a splat in that
//     view, background) - min(0, background); splat colours are >= 0), and
//     T_stop(p) the transmittance at which pixel p stopped (< transmittance_stop / 0.01; 0 when
//     it never stopped), every channel of every pixel changes by at most
//         D * (sum_{i in S} c_i(p) + T_stop(p))      where some i in S has c_i(p) > 0,
//     and not at all where none has. Proof: read the composite as the expected colour of the
//     first splat a ray stops at (splat j stops it with probability alpha_j); couple the two
//     renders through the same draws. They differ only when the first stop is a removed splat
//     (probability sum c_i(p) over the removed ones) or when the ray passes the point where the
//     original pixel stopped (probability T_stop(p)), and then by at most D. Each c_i(p) < c,
//     but many removed splats can meet at one pixel: the bound is per pixel, not c itself.
//     Add the float32 rounding of the two renders when comparing float32 images.
//   Other cameras or options may see the removed Gaussians: visibility is only measured at the
//   cameras given.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace avsplat {

struct PruneParams {
    /// Gaussians with opacity below this are removed; in [0, 1]. The default is the renderer's
    /// alpha threshold: such a Gaussian is never drawn.
    float min_opacity = 1.0f / 255.0f;
    /// Unset: with cameras, remove the Gaussians that take part in no pixel of any camera
    /// (exact). Set to c in [0, 1]: remove those whose contribution stays below c at every
    /// pixel of every camera (bound in the header comment).
    std::optional<float> min_contribution;
    /// The options of the renders that measure the contributions (backend is ignored: the CPU
    /// renderer computes contributions). Use the options the pruned cloud will be rendered with.
    RenderOptions render;
};

/// The pruned cloud and what was removed, by reason (each Gaussian counted once).
struct PruneResult {
    GaussianCloud cloud;
    std::size_t kept = 0;
    std::size_t removed = 0;
    std::size_t degenerate = 0;   ///< invalid (the validate()/sanitize() rule)
    std::size_t low_opacity = 0;  ///< opacity < min_opacity
    std::size_t invisible = 0;    ///< below min_contribution (or nowhere drawn) at every camera
    std::size_t cameras = 0;      ///< cameras the contributions were measured at
    /// The largest contribution_max (over the cameras) among the Gaussians removed as
    /// invisible: 0 with the default rule, below min_contribution otherwise.
    float max_removed_contribution = 0.0f;
    /// One line, e.g. "kept 900 of 1000; removed 100 (degenerate 2, low_opacity 30, invisible 68)".
    std::string summary() const;
};

/// Removes from `cloud` the Gaussians that cannot change an image (header comment).
/// Throws std::invalid_argument for a cloud whose array sizes are inconsistent, a bad parameter
/// (naming it) or a bad camera or render option (as render()).
/// Progress (avsplat/core/progress.h): cameras rendered, after each.
PruneResult prune(const GaussianCloud& cloud, const std::vector<Camera>& cameras = {},
                  const PruneParams& params = {});

}  // namespace avsplat
