// Real spherical harmonics colour evaluation, degree 0..3, with the constants and sign
// conventions of the 3DGS reference code and gsplat (so coefficients from either are
// interchangeable). Header-only and AVSPLAT_HD so that the CPU and CUDA renderers share it.
#pragma once

#include "avsplat/hostdevice.h"

namespace avsplat::sh {

constexpr double kC0 = 0.28209479177387814;
constexpr double kC1 = 0.4886025119029199;
constexpr double kC2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                           -1.0925484305920792, 0.5462742152960396};
constexpr double kC3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                           0.3731763325901154,  -0.4570457994644658, 1.445305721320277,
                           -0.5900435899266435};

/// Colour (before the +0.5 offset and clamping) of SH coefficients `coeffs` laid out [K][3]
/// for degree `degree` in the unit view direction (x, y, z). Bands above `degree` are never
/// read. Writes rgb[0..2].
template <class T>
AVSPLAT_HD void eval_sh(int degree, const float* coeffs, T x, T y, T z, T* rgb) {
    for (int c = 0; c < 3; ++c) rgb[c] = T(kC0) * T(coeffs[c]);
    if (degree < 1) return;
    const T b1[3] = {-T(kC1) * y, T(kC1) * z, -T(kC1) * x};
    for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) rgb[c] += b1[k] * T(coeffs[(1 + k) * 3 + c]);
    if (degree < 2) return;
    const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    const T b2[5] = {T(kC2[0]) * xy, T(kC2[1]) * yz, T(kC2[2]) * (T(2) * zz - xx - yy),
                     T(kC2[3]) * xz, T(kC2[4]) * (xx - yy)};
    for (int k = 0; k < 5; ++k)
        for (int c = 0; c < 3; ++c) rgb[c] += b2[k] * T(coeffs[(4 + k) * 3 + c]);
    if (degree < 3) return;
    const T b3[7] = {T(kC3[0]) * y * (T(3) * xx - yy),
                     T(kC3[1]) * xy * z,
                     T(kC3[2]) * y * (T(4) * zz - xx - yy),
                     T(kC3[3]) * z * (T(2) * zz - T(3) * xx - T(3) * yy),
                     T(kC3[4]) * x * (T(4) * zz - xx - yy),
                     T(kC3[5]) * z * (xx - yy),
                     T(kC3[6]) * x * (xx - T(3) * yy)};
    for (int k = 0; k < 7; ++k)
        for (int c = 0; c < 3; ++c) rgb[c] += b3[k] * T(coeffs[(9 + k) * 3 + c]);
}

/// RGB in [0, 1]-ish from a degree-0 coefficient: 0.5 + C0 * dc (not clamped).
template <class T>
AVSPLAT_HD T dc_to_color(T dc) { return T(0.5) + T(kC0) * dc; }

/// The degree-0 coefficient whose colour is `rgb`: (rgb - 0.5) / C0.
template <class T>
AVSPLAT_HD T color_to_dc(T rgb) { return (rgb - T(0.5)) / T(kC0); }

}  // namespace avsplat::sh
