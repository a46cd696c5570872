// Projection of 3D Gaussians to screen-space splats: the EWA / 3DGS forward projection with the
// conventions of gsplat (Kerbl et al. 2023; Zwicker et al. 2001), shared by the CPU reference
// renderer and the CUDA renderer.
//
// Everything here is header-only, uses no Eigen, no STL containers and no exceptions, and is
// marked AVSPLAT_HD so that nvcc compiles it as __host__ __device__. The building blocks are
// templated on the scalar T; project_gaussian runs them in double for both renderer precisions
// and rounds only the splat it writes to T (see "Precision" below).
//
// Storage conventions:
//   3x3 matrices     row-major T[9]
//   3x3 covariances  symmetric, upper triangle T[6] = (xx, xy, xz, yy, yz, zz)
//   2x2 covariances  symmetric T[3] = (xx, xy, yy); conics (inverse covariances) likewise
//   pixel coordinates: column u (x, right), row v (y, down); pixel (i, j) has its centre at
//   (i + 0.5, j + 0.5), as gsplat.
//
// The rules of one projection (project_gaussian):
//   1. culled unless near <= z <= far, z the camera-space depth of the mean (behind the camera
//      is z < near). z is the double depth of the stored float32 mean under the double view, and
//      near and far are the camera's doubles, never rounded: a mean stored as 0.01f
//      (= 0.0099999998) lies in front of a near plane at 0.01 and is culled, while z == near
//      exactly is a tie and is kept (the range is closed). Rounding near to float32 would make
//      that first case a tie in float32 only, kept there and culled in float64;
//   2. 2D covariance J W Sigma W^T J^T with the perspective Jacobian J at the mean, whose
//      x/z and y/z are clamped to 1.3 times the half field of view beyond the image (as 3DGS
//      and gsplat) so that means far outside the image do not get huge footprints;
//   3. low-pass filter: `low_pass` pixels^2 (0.3 in 3DGS) added to the diagonal; in
//      antialiased mode the opacity is multiplied by sqrt(det(cov) / det(cov + low_pass I)),
//      the Mip-Splatting / gsplat "antialiased" compensation;
//   4. culled when the 2D covariance is not positive definite or not finite, or when the
//      (compensated) opacity is below alpha_threshold (no pixel could reach it);
//   5. radius rule: the splat's box is the axis-aligned bounding box of its k-sigma ellipse
//      (k = extent_sigma, 3 by default), i.e. half-sizes radius_x = k sqrt(cov_xx) and
//      radius_y = k sqrt(cov_yy) around the projected mean. Only pixels whose centre lies in
//      that box (|u - mean_x| <= radius_x and |v - mean_y| <= radius_y) are ever blended with
//      the splat, whatever the tiling; the box is clipped to the image;
//   6. culled when the clipped box holds no pixel centre (the splat is outside the image). This
//      is the exact form of the usual "outside the image by more than a margin" test: a splat
//      is kept if and only if some pixel could receive it, so no margin parameter is needed.
//
// Precision. The float32 renderer is measured against the float64 one, so whether a Gaussian is
// kept must not depend on the precision; and the quantities the culling rules read are
// ill-conditioned for stiff Gaussians. A needle of scales 1e4 x 1e-8 x 1 has a 3D covariance
// with entries near 1e8, while the short axis of its 2D footprint comes from its axis of length
// 1: below the rounding error of those entries in float32 (about 6), so a float32 covariance
// and its 2D determinant are noise and rule 4 culled such needles at random. project_gaussian
// therefore computes everything up to the culling decisions in double whatever T is: the
// camera-space covariance (from the float32 scales and quaternion, which convert exactly), the
// 2D covariance, its determinant and inverse, the compensation, the opacity test and the box;
// the splat is rounded to T only when written, where rounding no longer decides anything. This
// is a few dozen double operations per Gaussian and none per pixel, so the float32 fast path
// keeps its speed (blending, per pixel, stays in T).
#pragma once

#include "avsplat/common/hostdevice.h"

#include <math.h>

namespace avsplat::projection {

namespace detail {
AVSPLAT_HD float sqrt_t(float x) { return sqrtf(x); }
AVSPLAT_HD double sqrt_t(double x) { return sqrt(x); }
AVSPLAT_HD float floor_t(float x) { return floorf(x); }
AVSPLAT_HD double floor_t(double x) { return floor(x); }
AVSPLAT_HD float ceil_t(float x) { return ceilf(x); }
AVSPLAT_HD double ceil_t(double x) { return ceil(x); }
}  // namespace detail

/// True when x is neither NaN nor infinite (x - x is NaN exactly for those).
template <class T>
AVSPLAT_HD bool is_finite(T x) { return x - x == T(0); }

/// Pinhole intrinsics in pixels and the image size.
template <class T>
struct Intrinsics {
    T fx, fy, cx, cy;
    int width, height;
};

/// What project_gaussian needs besides the Gaussian and the intrinsics (see the rules above),
/// in double for both renderer precisions (the camera's near and far are never rounded).
struct ProjectionParams {
    double near;             ///< camera-space z below which a mean is culled (> 0)
    double far;              ///< camera-space z above which a mean is culled
    double low_pass;         ///< added to the 2D covariance diagonal, pixels^2 (0.3 in 3DGS)
    double extent_sigma;     ///< k of the k-sigma box (3 in 3DGS)
    double alpha_threshold;  ///< smallest alpha that is blended (1/255 in 3DGS)
    bool antialiased;        ///< multiply opacity by the low-pass compensation (Mip-Splatting)
};

/// A projected Gaussian: everything the blending stage reads, apart from its colour, rounded to
/// the renderer's precision T.
template <class T>
struct Splat {
    T mean_x, mean_y;               ///< projected mean, pixels
    T conic_a, conic_b, conic_c;    ///< inverse 2D covariance (xx, xy, yy)
    T opacity;                      ///< opacity, times the compensation when antialiased
    T depth;                        ///< camera-space z of the mean (the sort key)
    T radius_x, radius_y;           ///< half-sizes of the k-sigma box, pixels
    int x_min, x_max, y_min, y_max; ///< inclusive pixel range of the box, clipped to the image
};

/// Covariance R S S^T R^T of a Gaussian with linear scales `scale` (3) and quaternion `quat`
/// (w, x, y, z; normalised here, must not be zero) as the upper triangle cov[6].
template <class T>
AVSPLAT_HD void covariance_3d(const float* quat, const float* scale, T* cov) {
    const T qw = T(quat[0]), qx = T(quat[1]), qy = T(quat[2]), qz = T(quat[3]);
    const T inv = T(1) / detail::sqrt_t(qw * qw + qx * qx + qy * qy + qz * qz);
    const T w = qw * inv, x = qx * inv, y = qy * inv, z = qz * inv;
    const T R[9] = {T(1) - T(2) * (y * y + z * z), T(2) * (x * y - w * z), T(2) * (x * z + w * y),
                    T(2) * (x * y + w * z), T(1) - T(2) * (x * x + z * z), T(2) * (y * z - w * x),
                    T(2) * (x * z - w * y), T(2) * (y * z + w * x), T(1) - T(2) * (x * x + y * y)};
    T M[9];  // R * diag(scale)
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) M[3 * r + c] = R[3 * r + c] * T(scale[c]);
    const int rows[6] = {0, 0, 0, 1, 1, 2}, cols[6] = {0, 1, 2, 1, 2, 2};
    for (int k = 0; k < 6; ++k) {
        const T* a = M + 3 * rows[k];
        const T* b = M + 3 * cols[k];
        cov[k] = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    }
}

/// out = R cov R^T for a rotation R (row-major 3x3) and an upper-triangle covariance.
template <class T>
AVSPLAT_HD void rotate_covariance(const T* R, const T* cov, T* out) {
    const T S[9] = {cov[0], cov[1], cov[2], cov[1], cov[3], cov[4], cov[2], cov[4], cov[5]};
    T RS[9];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            RS[3 * r + c] = R[3 * r] * S[c] + R[3 * r + 1] * S[3 + c] + R[3 * r + 2] * S[6 + c];
    const int rows[6] = {0, 0, 0, 1, 1, 2}, cols[6] = {0, 1, 2, 1, 2, 2};
    for (int k = 0; k < 6; ++k) {
        const T* a = RS + 3 * rows[k];
        const T* b = R + 3 * cols[k];
        out[k] = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    }
}

/// out = R p + t (world to camera for R, t of a world_to_camera matrix).
template <class T>
AVSPLAT_HD void transform_point(const T* R, const T* t, const T* p, T* out) {
    for (int r = 0; r < 3; ++r)
        out[r] = R[3 * r] * p[0] + R[3 * r + 1] * p[1] + R[3 * r + 2] * p[2] + t[r];
}

/// Rule 1: true when the camera-space depth z lies in the closed range [near, far] (z < near
/// includes behind the camera; z == near is kept). Double only, so that both renderer
/// precisions decide on the same depth and the same planes.
AVSPLAT_HD bool in_depth_range(double z, double near, double far) { return z >= near && z <= far; }

/// Projects the camera-space mean `mean_c` (z > 0) to pixels and the camera-space covariance
/// `cov_c` (upper triangle) to the 2D covariance J cov_c J^T, cov2d = (xx, xy, yy). The
/// Jacobian is taken at the mean with x/z and y/z clamped to the image plus 0.3 half fields of
/// view on each side, as 3DGS and gsplat.
template <class T>
AVSPLAT_HD void project_mean_covariance(const T* mean_c, const T* cov_c, const Intrinsics<T>& K,
                                        T* mean2d, T* cov2d) {
    const T x = mean_c[0], y = mean_c[1], z = mean_c[2];
    const T rz = T(1) / z;
    mean2d[0] = K.fx * x * rz + K.cx;
    mean2d[1] = K.fy * y * rz + K.cy;
    const T tan_x = T(0.5) * T(K.width) / K.fx, tan_y = T(0.5) * T(K.height) / K.fy;
    const T lim_x_pos = (T(K.width) - K.cx) / K.fx + T(0.3) * tan_x;
    const T lim_x_neg = K.cx / K.fx + T(0.3) * tan_x;
    const T lim_y_pos = (T(K.height) - K.cy) / K.fy + T(0.3) * tan_y;
    const T lim_y_neg = K.cy / K.fy + T(0.3) * tan_y;
    T u = x * rz, v = y * rz;
    u = u < -lim_x_neg ? -lim_x_neg : (u > lim_x_pos ? lim_x_pos : u);
    v = v < -lim_y_neg ? -lim_y_neg : (v > lim_y_pos ? lim_y_pos : v);
    // J = [fx/z, 0, -fx u/z; 0, fy/z, -fy v/z] with the clamped u = x/z, v = y/z.
    const T j00 = K.fx * rz, j02 = -K.fx * u * rz, j11 = K.fy * rz, j12 = -K.fy * v * rz;
    const T sxx = cov_c[0], sxy = cov_c[1], sxz = cov_c[2], syy = cov_c[3], syz = cov_c[4],
            szz = cov_c[5];
    // Row 0 (a) and the needed part of row 1 (b) of J * Sigma.
    const T a0 = j00 * sxx + j02 * sxz, a1 = j00 * sxy + j02 * syz, a2 = j00 * sxz + j02 * szz;
    const T b1 = j11 * syy + j12 * syz, b2 = j11 * syz + j12 * szz;
    cov2d[0] = a0 * j00 + a2 * j02;
    cov2d[1] = a1 * j11 + a2 * j12;
    cov2d[2] = b1 * j11 + b2 * j12;
}

/// det(cov2d) = xx yy - xy^2 in double: for float inputs the products are exact, so the
/// cancellation of a thin (needle-like) splat does not turn the determinant into noise.
template <class T>
AVSPLAT_HD double det_2d(const T* cov2d) {
    return double(cov2d[0]) * double(cov2d[2]) - double(cov2d[1]) * double(cov2d[1]);
}

/// Adds `low_pass` to the diagonal of cov2d and returns the antialiasing compensation
/// sqrt(max(0, det before / det after)) (Mip-Splatting; 0 when det after <= 0).
template <class T>
AVSPLAT_HD T add_low_pass(T* cov2d, T low_pass) {
    const double det_orig = det_2d(cov2d);
    cov2d[0] += low_pass;
    cov2d[2] += low_pass;
    const double det_blur = det_2d(cov2d);
    if (!(det_blur > 0.0)) return T(0);
    const double ratio = det_orig / det_blur;
    return ratio > 0.0 ? T(sqrt(ratio)) : T(0);
}

/// conic = inverse of cov2d (xx, xy, yy). Returns false, leaving conic unspecified, when cov2d
/// is not positive definite or the inverse is not finite.
template <class T>
AVSPLAT_HD bool invert_covariance_2d(const T* cov2d, T* conic) {
    const double det = det_2d(cov2d);
    if (!(det > 0.0) || !is_finite(det) || !(cov2d[0] > T(0))) return false;
    const double inv = 1.0 / det;
    conic[0] = T(double(cov2d[2]) * inv);
    conic[1] = T(-double(cov2d[1]) * inv);
    conic[2] = T(double(cov2d[0]) * inv);
    return is_finite(conic[0]) && is_finite(conic[1]) && is_finite(conic[2]);
}

/// The radius rule: half-sizes of the axis-aligned box of the k-sigma ellipse
/// {d : d^T cov2d^-1 d <= k^2}, radius = (k sqrt(cov_xx), k sqrt(cov_yy)).
template <class T>
AVSPLAT_HD void splat_radius(const T* cov2d, T extent_sigma, T* radius) {
    radius[0] = extent_sigma * detail::sqrt_t(cov2d[0]);
    radius[1] = extent_sigma * detail::sqrt_t(cov2d[2]);
}

/// The pixels i in [0, size) whose centre i + 0.5 lies in [center - radius, center + radius]:
/// writes the inclusive range [lo, hi] and returns true, or returns false when there is none.
/// Safe for huge or non-finite values (compared before any conversion to int).
template <class T>
AVSPLAT_HD bool pixel_span(T center, T radius, int size, int& lo, int& hi) {
    T l = detail::ceil_t(center - radius - T(0.5));
    T h = detail::floor_t(center + radius - T(0.5));
    if (!(l <= h)) return false;  // empty, or NaN
    l = l > T(0) ? l : T(0);
    h = h < T(size - 1) ? h : T(size - 1);
    if (!(l <= h)) return false;
    lo = int(l);
    hi = int(h);
    return true;
}

/// Projects one Gaussian given its camera-space mean `mean_c` (3) and covariance `cov_c` (upper
/// triangle, 6), both in double, and its opacity. Applies the rules in the header comment in
/// double and writes the splat rounded to T; returns false when the Gaussian is culled (then
/// `out` is unspecified). The decision does not depend on T.
template <class T>
AVSPLAT_HD bool project_gaussian(const double* mean_c, const double* cov_c, double opacity,
                                 const Intrinsics<double>& K, const ProjectionParams& p,
                                 Splat<T>& out) {
    if (!in_depth_range(mean_c[2], p.near, p.far)) return false;
    double mean2d[2], cov2d[3], conic[3], radius[2];
    project_mean_covariance(mean_c, cov_c, K, mean2d, cov2d);
    const double compensation = add_low_pass(cov2d, p.low_pass);
    if (!invert_covariance_2d(cov2d, conic)) return false;
    const double alpha_max = p.antialiased ? opacity * compensation : opacity;
    if (!(alpha_max >= p.alpha_threshold)) return false;
    splat_radius(cov2d, p.extent_sigma, radius);
    if (!pixel_span(mean2d[0], radius[0], K.width, out.x_min, out.x_max)) return false;
    if (!pixel_span(mean2d[1], radius[1], K.height, out.y_min, out.y_max)) return false;
    out.mean_x = T(mean2d[0]);
    out.mean_y = T(mean2d[1]);
    out.conic_a = T(conic[0]);
    out.conic_b = T(conic[1]);
    out.conic_c = T(conic[2]);
    out.opacity = T(alpha_max);
    out.depth = T(mean_c[2]);
    out.radius_x = T(radius[0]);
    out.radius_y = T(radius[1]);
    return true;
}

}  // namespace avsplat::projection
