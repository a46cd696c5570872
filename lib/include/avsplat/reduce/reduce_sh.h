// reduce_sh: drop the spherical-harmonic bands whose share of the colour stays below a bound in
// every view direction.
//
// The bound (provably safe, not a sampled estimate). For band l of one colour channel with
// coefficients c_lm (m = -l..l), the basis of core/sh.h is orthonormal, so by Cauchy-Schwarz and
// the addition theorem sum_m Y_lm(d)^2 = (2l + 1) / (4 pi) for every unit direction d:
//     max_d |sum_m c_lm Y_lm(d)| <= sqrt((2l + 1) / (4 pi)) ||c_l||_2.
// (It is exact for bands whose coefficients are those of a zonal harmonic about some axis, and
// within a factor sqrt(2l + 1) otherwise.) Dropping bands d+1..D changes the channel's value by
// at most the sum of their bounds; the renderer's clamp of SH + 0.5 at 0 is 1-Lipschitz, so the
// splat colour moves no more; a pixel is sum_i w_i rgb_i + T background with weights that do
// not depend on the SH, so it moves by at most (1 - T) times the largest bound, i.e. by no more
// than the bound (plus the renderer's float32 rounding). The error of a Gaussian is the largest
// of its three channels' bounds.
//
// The cloud has one sh_degree: the result's is the smallest degree at which the dropped bands'
// bound is <= max_error for every Gaussian; the per-Gaussian smallest degrees are reported as a
// histogram. Coefficients of bands above the result's degree are not stored, so the renderer
// (core/sh.h evaluates bands up to sh_degree only) and the writers (3DGS PLY writes
// (degree + 1)^2 - 1 f_rest per channel; .splat keeps the DC term only) never see them.
#pragma once

#include "avsplat/core/gaussians.h"

#include <array>
#include <cstddef>
#include <string>

namespace avsplat {

/// The reduced cloud, the bound it meets and what it saves.
struct ReduceShResult {
    GaussianCloud cloud;        ///< sh_degree = the chosen degree; everything else as the input
    int sh_degree_before = 0;   ///< the input's degree
    int sh_degree = 0;          ///< the chosen degree (cloud.sh_degree)
    /// The bound achieved: max over Gaussians and channels of the dropped bands' bound (colour
    /// units; 0 when no band was dropped).
    double max_error_bound = 0.0;
    /// Bytes of SH coefficients saved: N ((D + 1)^2 - (d + 1)^2) 3 floats of 4 bytes, in memory
    /// and in a 3DGS PLY (f_rest).
    std::size_t bytes_saved = 0;
    /// gaussians_by_degree[k]: Gaussians whose own smallest degree meeting max_error is k.
    /// With a forced degree, the same histogram for the max_error given.
    std::array<std::size_t, 4> gaussians_by_degree{};
    /// One line, e.g. "degree 3 -> 1, bound 0.0031, 1.9 MB saved; per Gaussian 0: 10, 1: 90, 2: 0, 3: 0".
    std::string summary() const;
};

/// Drops SH bands of `cloud` (header comment). `max_error` >= 0, finite: the largest colour
/// change allowed (1/255 is one 8-bit level). `degree` in 0..cloud.sh_degree forces the result's
/// degree (max_error then only feeds the histogram); -1 (default) chooses the smallest degree
/// meeting max_error. Throws std::invalid_argument for an invalid cloud (validate()) or a bad
/// argument, naming it.
ReduceShResult reduce_sh(const GaussianCloud& cloud, double max_error = 1.0 / 255.0, int degree = -1);

/// The bound of reduce_sh for one Gaussian: max over its three channels of the sum over bands
/// l = degree+1..sh_degree of sqrt((2l + 1) / (4 pi)) ||c_l||_2. `sh` points at its
/// (sh_degree + 1)^2 x 3 coefficients.
double sh_truncation_bound(const float* sh, int sh_degree, int degree);

}  // namespace avsplat
