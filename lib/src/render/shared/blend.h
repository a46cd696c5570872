// Per-pixel evaluation of a projected splat and front-to-back alpha compositing, the 3DGS
// rules, shared by the CPU reference renderer and the CUDA renderer.
//
// Header-only, templated on the scalar T, no Eigen, no STL, no exceptions, AVSPLAT_HD.
//
// For a pixel centre p and a splat with projected mean m, conic (a, b, c) and opacity o:
//   d = p - m,  power = -0.5 (a dx^2 + c dy^2) - b dx dy
//   alpha = min(0.99, o exp(power)),  and alpha = 0 when power > 0 (a conic made indefinite by
//   rounding; 3DGS skips these too), so alpha never exceeds o.
// Compositing, front to back, starting from transmittance T = 1:
//   a splat with alpha < alpha_threshold (1/255) is skipped;
//   when T (1 - alpha) < transmittance_stop (1e-4) the pixel is saturated: this splat is not
//   blended and no later splat is looked at (the 3DGS rule);
//   otherwise the splat gets weight w = alpha T, colour += w rgb, depth += w z, T *= 1 - alpha.
// Finally colour += T background, alpha = 1 - T and the expected depth is
// sum(w z) / (1 - T), 0 where nothing was blended (gsplat's "ED" render mode).
#pragma once

#include "avsplat/common/hostdevice.h"
#include "common/exp_poly.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

namespace avsplat::blend {

/// Largest alpha a single splat may have (3DGS): keeps T > 0 so that later splats still count.
template <class T>
AVSPLAT_HD T max_alpha() { return T(0.99); }

/// The exponent of the splat's Gaussian at offset (dx, dy) from its mean.
template <class T>
AVSPLAT_HD T gaussian_power(T conic_a, T conic_b, T conic_c, T dx, T dy) {
    return T(-0.5) * (conic_a * dx * dx + conic_c * dy * dy) - conic_b * dx * dy;
}

/// exp(x) for x <= 0 in float: Cody-Waite reduction x = n ln 2 + r and Cephes' degree-6
/// polynomial for exp(r), error at most about 1 ulp (0.95 ulp, 7.7e-8 relative, against exp in
/// double over [-87, 0], tests/cpp/test_render_kernels.cpp); 0 below -87 (where
/// expf leaves the normal range) and for NaN; x > 0 is treated as 0. Written with plain
/// arithmetic and a bit cast so that the CPU loop vectorises and CUDA runs the same operations.
AVSPLAT_HD float exp_nonpositive(float x) {
    const float xc = x >= -87.0f ? (x <= 0.0f ? x : 0.0f) : -87.0f;
    // Adding 1.5 * 2^23 rounds x log2(e) to the nearest integer n (default rounding mode).
    const float shifted = xc * exp_poly::kLog2e + exp_poly::kRoundShift;
    const float n = shifted - exp_poly::kRoundShift;
    float r = xc - n * exp_poly::kLn2Hi;
    r = r - n * exp_poly::kLn2Lo;
    float p = exp_poly::kP0;
    p = p * r + exp_poly::kP1;
    p = p * r + exp_poly::kP2;
    p = p * r + exp_poly::kP3;
    p = p * r + exp_poly::kP4;
    p = p * r + exp_poly::kP5;
    p = p * (r * r) + r + 1.0f;
    // 2^n for n in [-126, 0]: biased exponent n + 127 in [1, 127], a normal float.
    const uint32_t bits = uint32_t(int(n) + 127) << 23;
#if defined(__CUDA_ARCH__)
    const float scale = __uint_as_float(bits);
#else
    float scale;
    memcpy(&scale, &bits, sizeof scale);
#endif
    return x >= -87.0f ? p * scale : 0.0f;
}

/// exp(x) for x <= 0 in double (the reference path uses the library exp); x > 0 is treated as 0
/// and NaN gives 0, as the float version.
AVSPLAT_HD double exp_nonpositive(double x) {
    return x >= -745.0 ? exp(x <= 0.0 ? x : 0.0) : 0.0;
}

/// alpha = min(0.99, opacity exp(power)), 0 when power > 0.
template <class T>
AVSPLAT_HD T splat_alpha(T opacity, T power) {
    const T a = opacity * exp_nonpositive(power);
    const T clamped = a < max_alpha<T>() ? a : max_alpha<T>();
    return power <= T(0) ? clamped : T(0);
}

/// The outcome of one compositing step of a splat at a pixel. The flags are 0 or 1 as int (not
/// bool) so that a loop over pixels mixing them with 32-bit floats vectorises.
template <class T>
struct BlendStep {
    T weight;              ///< alpha T: the splat's share of the pixel (0 unless blended)
    T next_transmittance;  ///< T (1 - alpha) when blended, else T unchanged
    int blended;           ///< 1 when the splat contributes to this pixel
    int saturated;         ///< 1 when the pixel is done: neither this splat nor any later one is blended
};

/// One front-to-back step for a splat of opacity `alpha` at a pixel of transmittance
/// `transmittance` (rules in the header comment). Branch-free, so that a CPU loop over pixels
/// vectorises; the caller stops visiting a pixel once `saturated` is returned.
template <class T>
AVSPLAT_HD BlendStep<T> blend_step(T alpha, T transmittance, T alpha_threshold,
                                   T transmittance_stop) {
    const T next = transmittance * (T(1) - alpha);
    const int visible = alpha >= alpha_threshold;
    const int saturated = visible & int(next < transmittance_stop);
    const int blended = visible & int(next >= transmittance_stop);
    BlendStep<T> s;
    s.weight = blended ? alpha * transmittance : T(0);
    s.next_transmittance = blended ? next : transmittance;
    s.blended = blended;
    s.saturated = saturated;
    return s;
}

/// The final values of a pixel from its accumulators: rgb = colour + T background,
/// alpha = 1 - T, depth = depth_sum / alpha (0 when alpha is 0).
template <class T>
AVSPLAT_HD void finish_pixel(T transmittance, const T* color_sum, T depth_sum,
                             const T* background, T* rgb, T& alpha, T& depth) {
    for (int c = 0; c < 3; ++c) rgb[c] = color_sum[c] + transmittance * background[c];
    alpha = T(1) - transmittance;
    depth = alpha > T(0) ? depth_sum / alpha : T(0);
}

}  // namespace avsplat::blend
