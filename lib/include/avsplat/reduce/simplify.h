// simplify: reduce a scene to a budget of Gaussians with the least image error.
//
// The budget is one of: a target count, a ratio of the input count, or a rendered error bound at
// given cameras. Two methods:
//
//   Merge  pairwise merging of nearby Gaussians by moment matching, in rounds (the way
//          PlayCanvas's splat-transform `--decimate` works; our own merge cost). Each round:
//          a KD-tree on the means gives every Gaussian its nearest neighbours, 8 in the first
//          round and 12 in the later ones (exact, ties by the nearer index, so equal Gaussians
//          pair up; fewer than splat-transform's 16: 1.4x faster, see the report); each candidate
//          pair (i, j) gets the cost below; pairs are taken greedily in increasing cost (ties by
//          the smaller, then the larger index) when both ends are still free, until the round has
//          removed min(n - target, floor(0.4 n)) Gaussians; each pair is replaced by its moment
//          match. Rounds repeat until the target is met, so the count is met exactly. The rows
//          are put in Morton order of their means first (ties in the canonical order below):
//          the indices above are rows in that order, a merged row takes the place of its first
//          member, and the result comes out in that order. (A round
//          that must pair up half of the cloud ends with its worst pairs; rounds of at most 40 %
//          recompute neighbours and costs in between, which measured better; see the report.)
//            mass      w = opacity * ellipsoid surface area (Knud Thomsen's approximation): by
//                      Cauchy's formula a quarter of the surface area is the mean projected area
//                      over view directions, so w is proportional to the view-averaged "ink" of
//                      the splat on the image. Weights pi_k = w_k / (w_i + w_j).
//            merged    mean mu = sum pi_k mu_k; covariance Sigma = sum pi_k (Sigma_k + d_k d_k^T),
//                      d_k = mu_k - mu (the law of total variance); scales sqrt(eigenvalues),
//                      increasing, rotation of the eigenvectors (det +1, w >= 0); SH, confidence
//                      and extra channels sum pi_k x_k; opacity min(1, W / S) with
//                      W = w_i + w_j and S the merged surface area (the ink is conserved up to
//                      an opacity of 1; a merged point, S = 0, keeps the larger opacity).
//            cost      G + 2 L + C + F:
//                      G = (ln det S - pi_i ln det S_i - pi_j ln det S_j) / 2, clamped at 0,
//                          S = Sigma + delta^2 I, delta^2 = 1e-4 tr(Sigma) / 3 (S_i, S_j
//                          alike): Runnalls' upper bound on the KL divergence of the pair from
//                          its moment match (size and shape: two flat surfels side by side cost
//                          little, stacked along their normals a lot). The floor keeps flat and
//                          needle Gaussians (determinant 0) finite and the cost scale-invariant;
//                      L = max(0, 1 - o S / W): the share of the ink lost to the opacity cap
//                          (opacity: two opaque Gaussians that overlap cannot keep their ink);
//                          weighted 2: closer to the unreduced renders at 1/8 and 1/16 on the
//                          report's scenes than 1 (and on its held-out scene, see the report);
//                      C = 30 pi_i pi_j C0^2 (2 |dc_i - dc_j|^2 + |rest_i - rest_j|^2),
//                          C0 = 0.2821 (the SH degree-0 constant), dc the three degree-0
//                          coefficients, rest the higher bands': the view-averaged squared
//                          colour difference of the pair (orthonormal SH: the mean over
//                          directions of the squared colour difference is C0^2 times the
//                          squared coefficient difference; with pi_i pi_j, Ward's criterion),
//                          the DC part counted twice (it shows from every direction; a higher
//                          band's difference changes sign over the sphere). The weights 30 and
//                          2 were chosen on the scenes of the reduction report (10, 30 and 100
//                          were within 0.6 dB of each other there; DC 2 against 1 put the
//                          embedded scene's SSIM at 1/8 and 1/16 ahead of splat-transform's).
//                      F = w |o_i k_i + o_j k_j - o k|^2: the squared L2 distance between the
//                          amplitude fields (opacity x unnormalised kernel exp(-x^T S^-1 x / 2),
//                          colour left out) of the pair and of their merge, in closed form (six
//                          Gaussian products), on covariances with a floor of 1e-6 tr(Sigma) / 3
//                          (100 times below G's: a far pair's members must not be thickened to
//                          the merge's scale). Unlike G it grows with the Gaussians' volume and
//                          opacity, so large opaque Gaussians are kept whole for longer, as in
//                          splat-transform's `--decimate-adaptive`, whose cost is such an L2
//                          distance. w = 0.072 sqrt(target / N) / the input's median field
//                          energy (pi^(3/2) o^2 sqrt(det S) of each Gaussian), so F does not
//                          change with the scene's scale, and is weaker for deeper reductions,
//                          where merged Gaussians (and F with their volume) are larger;
//                      each pair's F is further weighted by the exposure of its ends,
//                          exp(-0.6 (c_i + c_j) / 2), c the cover of a Gaussian: the sum over its
//                          candidate list of o_k exp(-d^T (Sigma + Sigma_k)^-1 d / 2), its
//                          neighbours' amplitude at its centre. A merge where the scene is covered
//                          many times over hides behind the cover (as a transmittance exp(-0.6 c)
//                          would say); among few or transparent neighbours (floaters, edges, thin
//                          parts) it shows. Without the exposure F lost up to 0.9 dB against no F
//                          on dense scenes; with it F gains 1-4 dB on the report's trained-like
//                          scenes at every ratio (see the report, and moment_merge.h for the
//                          weights tried).
//                      The weights pi (opacity x area) make faint and tiny Gaussians follow
//                      their partner: merging them costs little and moves little.
//          Zero-mass pairs (opacity 0, or zero scales) weigh by opacity, then equally.
//
//   Voxel  occupancy-guided fusion (fuse_gaussians, policy Occupancy, shape Moment) at the voxel
//          size found by bisection on log(voxel size): the occupied-voxel count falls (not
//          strictly monotonically, but nearly) as the voxel grows, so bisection between a voxel
//          that keeps every distinct position and one that holds the whole cloud finds a size
//          whose count is within 2 % of the target in a few tens of steps (at most 64). When no
//          size meets 2 % (e.g. fewer distinct positions than the target), the size whose count
//          is closest to the target is used and output_count says what it gave. A cloud without
//          a confidence gets one from its opacity: logit(clamp(opacity, 1e-6, 1 - 1e-6)), read
//          with the Logit mapping, so opaque Gaussians dominate their voxel (the output carries
//          no confidence then).
//
// With max_error and cameras, the count is the smallest that keeps the rendered error at or
// under max_error, found by bisection on log(count) (12 steps, or until the bracket is within 2 %).
// The error is the root mean square difference of the rendered colour (RGB in [0, 1], over every
// pixel, channel and camera) between the simplified and the input cloud, rendered with
// SimplifyOptions::render. Whenever cameras are given, `error` is measured for the result.
//
// Determinism. Both methods put the input in a canonical order first (by the bits of the mean,
// then of every other field), so results are bit-identical for any permutation of the input and
// any number of OpenMP threads.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"

#include <cstddef>
#include <functional>
#include <optional>
#include <vector>

namespace avsplat {

enum class SimplifyMethod { Merge, Voxel };

/// The budget (exactly one of target_count, ratio, max_error) and the method.
struct SimplifyOptions {
    std::optional<std::size_t> target_count;  ///< >= 1; a target >= N returns the input
    std::optional<double> ratio;              ///< in (0, 1]; target = max(1, round(ratio * N))
    std::optional<double> max_error;          ///< > 0, RMSE of rendered colour; needs cameras
    SimplifyMethod method = SimplifyMethod::Merge;
    RenderOptions render;                     ///< how `error` is rendered (CPU by default)
    /// With max_error: called after each simplification the search tries, with the number tried
    /// and the most it can try (kMaxErrorSearches); for a progress display. Unset: not called.
    std::function<void(int tried, int most)> progress;
};

/// The most simplifications a max_error search tries (the count 1, then a bisection).
constexpr int kMaxErrorSearches = 13;

/// Throws std::invalid_argument naming the first bad field ("SimplifyOptions.ratio: ...").
void validate(const SimplifyOptions& options);

/// What simplify did.
struct SimplifyResult {
    GaussianCloud cloud;            ///< the simplified cloud
    std::size_t input_count = 0;    ///< N
    std::size_t target_count = 0;   ///< the count asked for (or found, with max_error)
    std::size_t output_count = 0;   ///< cloud.size()
    SimplifyMethod method = SimplifyMethod::Merge;
    /// Voxel: the voxel size used. Merge: NaN.
    double voxel_size = 0.0;
    /// Merge: merge rounds. Voxel: bisection steps on the voxel size.
    int iterations = 0;
    /// RMSE of rendered colour against the input at the given cameras; NaN without cameras.
    double error = 0.0;
    /// With max_error: the simplifications tried by the search on the count; else 1.
    int searches = 1;
};

/// Simplifies `cloud` to the budget in `options` (see the file comment for the methods).
///   cloud    a valid cloud (validate()); its SH degree, confidence and extras are kept
///   cameras  where the error is measured; required with max_error, optional otherwise
/// Throws std::invalid_argument for an invalid cloud (naming the field and index), a bad option,
/// max_error without cameras or an invalid camera; avsplat::Interrupted when the caller's
/// interrupt check says stop.
SimplifyResult simplify(const GaussianCloud& cloud, const SimplifyOptions& options,
                        const std::vector<Camera>& cameras = {});

}  // namespace avsplat
