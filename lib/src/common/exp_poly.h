// The constants of the library's float exp: Cody-Waite reduction x = n ln 2 + r (ln 2 split in a
// 9-bit high part, so n * kLn2Hi is exact, and a low part) and Cephes' degree-6 polynomial for
// exp(r) on |r| <= ln 2 / 2. One set for every implementation: the renderer's scalar
// blend::exp_nonpositive (CPU and CUDA), its AVX2 and AVX-512 tile kernels (the same operations
// lane by lane) and the fusion's SSE2 weights (voxel_weights.h). Scalar constexpr, so CUDA device
// code may read them directly.
#pragma once

namespace avsplat::exp_poly {

constexpr float kLog2e = 1.44269504088896341f;
/// 1.5 * 2^23: adding it rounds a float of magnitude below 2^22 to an integer (default rounding).
constexpr float kRoundShift = 12582912.0f;
constexpr float kLn2Hi = 0.693359375f;
constexpr float kLn2Lo = -2.12194440e-4f;
/// exp(r) ~ 1 + r + r^2 (kP0 r^5 + kP1 r^4 + kP2 r^3 + kP3 r^2 + kP4 r + kP5).
constexpr float kP0 = 1.9875691500e-4f;
constexpr float kP1 = 1.3981999507e-3f;
constexpr float kP2 = 8.3334519073e-3f;
constexpr float kP3 = 4.1665795894e-2f;
constexpr float kP4 = 1.6666665459e-1f;
constexpr float kP5 = 5.0000001201e-1f;

}  // namespace avsplat::exp_poly
