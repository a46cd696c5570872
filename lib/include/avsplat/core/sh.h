// Real spherical harmonics colour evaluation, degree 0..3, with the constants and sign
// conventions of the 3DGS reference code and gsplat (so coefficients from either are
// interchangeable). Header-only and AVSPLAT_HD so that the CPU and CUDA renderers share it.
//
// The basis is the real SH with the Condon-Shortley phase, ordered m = -l..l within band l:
//   band 1: -C1 y, C1 z, -C1 x
//   band 2: C2 xy, -C2 yz, C2' (2z^2 - x^2 - y^2), -C2 xz, C2'' (x^2 - y^2)
//   band 3: the seven cubic terms below, signs alternating with odd m.
// The constants are literals inside eval_sh (not constexpr arrays) because namespace-scope
// arrays cannot be read from CUDA device code; kC0 and kC1 are scalars, which device code may use.
#pragma once

#include "avsplat/common/hostdevice.h"

namespace avsplat::sh {

/// Normalisation of band 0: 1 / (2 sqrt(pi)).
constexpr double kC0 = 0.28209479177387814;
/// Normalisation of band 1: sqrt(3) / (2 sqrt(pi)).
constexpr double kC1 = 0.4886025119029199;

/// Colour (before the +0.5 offset and clamping) of SH coefficients `coeffs` laid out [K][3]
/// (K = (degree + 1)^2, degree 0 first) for degree `degree` in 0..3, in the unit view direction
/// (x, y, z) pointing from the camera centre to the Gaussian. Bands above `degree` are never
/// read or evaluated. Writes rgb[0..2].
template <class T>
AVSPLAT_HD void eval_sh(int degree, const float* coeffs, T x, T y, T z, T* rgb) {
    for (int c = 0; c < 3; ++c) rgb[c] = T(kC0) * T(coeffs[c]);
    if (degree < 1) return;
    const T c1 = T(kC1);
    const T b1[3] = {-c1 * y, c1 * z, -c1 * x};
    for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) rgb[c] += b1[k] * T(coeffs[(1 + k) * 3 + c]);
    if (degree < 2) return;
    const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    const T b2[5] = {T(1.0925484305920792) * xy,
                     T(-1.0925484305920792) * yz,
                     T(0.31539156525252005) * (T(2) * zz - xx - yy),
                     T(-1.0925484305920792) * xz,
                     T(0.5462742152960396) * (xx - yy)};
    for (int k = 0; k < 5; ++k)
        for (int c = 0; c < 3; ++c) rgb[c] += b2[k] * T(coeffs[(4 + k) * 3 + c]);
    if (degree < 3) return;
    const T b3[7] = {T(-0.5900435899266435) * y * (T(3) * xx - yy),
                     T(2.890611442640554) * xy * z,
                     T(-0.4570457994644658) * y * (T(4) * zz - xx - yy),
                     T(0.3731763325901154) * z * (T(2) * zz - T(3) * xx - T(3) * yy),
                     T(-0.4570457994644658) * x * (T(4) * zz - xx - yy),
                     T(1.445305721320277) * z * (xx - yy),
                     T(-0.5900435899266435) * x * (xx - T(3) * yy)};
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
