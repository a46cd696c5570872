// The per-Gaussian preprocessing of both renderers: camera transform, covariance, projection
// and culling (projection.h), view direction and SH colour (sh.h). The CPU renderer
// (render_cpu.cpp) calls project_record from its OpenMP loop, the CUDA renderer from its
// projection kernel (cuda/kernel_bodies.h, render_cuda.cu), so both back ends run literally the same
// operations in the same order; with IEEE arithmetic on both sides (the CUDA sources are
// compiled with --fmad=false) they produce the same bits:
//   - camera-space mean and covariance, projection and culling in double whatever T (so that
//     float32 and float64 keep the same Gaussians, see projection.h "Precision"), the splat
//     rounded to T; view direction for SH in double;
//   - colour = max(SH + 0.5, 0) in T, evaluated once per Gaussian.
//
// Header-only, AVSPLAT_HD, no Eigen, no STL, no exceptions. The host-side construction of
// ViewParams from a Camera is view_params.h (it needs Eigen, which nvcc must not parse).
#pragma once

#include "avsplat/common/hostdevice.h"
#include "render/shared/projection.h"
#include "avsplat/core/sh.h"
#include "render/shared/tiling.h"

#include <math.h>
#include <stdint.h>

namespace avsplat::preprocess {

/// Everything the projection of one Gaussian needs about the view, built once per frame on the
/// host (view_params.h) and, on the GPU, passed to the kernel by value. T is the precision of
/// the records project_record writes; the view itself is double for both precisions, because
/// the projection that decides culling is (projection.h, "Precision").
template <class T>
struct ViewParams {
    double R[9];    ///< rotation block of world_to_camera, row-major
    double t[3];    ///< translation column of world_to_camera
    projection::Intrinsics<double> K;
    projection::ProjectionParams proj;
    int sh_degree;  ///< 0..3
};

/// Projects one Gaussian, culls it and evaluates its colour into `rec`.
///
/// `mean` (3), `scale` (3), `quat` (4, w x y z) and `sh` ((sh_degree + 1)^2 x 3) point at the
/// Gaussian's rows of GaussianCloud-layout float arrays; `opacity` is its opacity.
/// `Record` is the renderer's splat record: any struct with members mean_x, mean_y, conic_a,
/// conic_b, conic_c, opacity, depth, rgb[3] of type T and int x_min, x_max, y_min, y_max (the
/// two renderers lay it out differently: cache-line aligned on the CPU, packed on the GPU).
/// Returns the number of 16 x 16 tiles the splat's clipped pixel box meets, 0 when the Gaussian
/// is culled (then `rec` is left partly written and must not be read).
template <class T, class Record>
AVSPLAT_HD uint32_t project_record(const ViewParams<T>& v, const float* mean, const float* scale,
                                   const float* quat, float opacity, const float* sh, Record& rec) {
    const double m[3] = {double(mean[0]), double(mean[1]), double(mean[2])};
    double mean_c[3];
    projection::transform_point(v.R, v.t, m, mean_c);
    double cov[6], cov_c[6];
    projection::covariance_3d(quat, scale, cov);
    projection::rotate_covariance(v.R, cov, cov_c);
    projection::Splat<T> s;
    if (!projection::project_gaussian(mean_c, cov_c, double(opacity), v.K, v.proj, s)) return 0;
    rec.mean_x = s.mean_x;
    rec.mean_y = s.mean_y;
    rec.conic_a = s.conic_a;
    rec.conic_b = s.conic_b;
    rec.conic_c = s.conic_c;
    rec.opacity = s.opacity;
    rec.depth = s.depth;
    rec.x_min = s.x_min;
    rec.x_max = s.x_max;
    rec.y_min = s.y_min;
    rec.y_max = s.y_max;
    // View direction camera centre -> mean in world axes, R^T mean_c; its length is >= near > 0.
    T dir[3] = {T(0), T(0), T(0)};
    if (v.sh_degree > 0) {
        double d[3];
        for (int c = 0; c < 3; ++c)
            d[c] = v.R[c] * mean_c[0] + v.R[3 + c] * mean_c[1] + v.R[6 + c] * mean_c[2];
        const double inv = 1.0 / sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        for (int c = 0; c < 3; ++c) dir[c] = T(d[c] * inv);
    }
    sh::eval_sh(v.sh_degree, sh, dir[0], dir[1], dir[2], rec.rgb);
    for (int c = 0; c < 3; ++c) {
        const T x = rec.rgb[c] + T(0.5);
        rec.rgb[c] = x < T(0) ? T(0) : x;  // clamped at 0, not at 1 (3DGS); NaN passes through
    }
    return uint32_t(tiling::tile_count(tiling::tile_rect(s.x_min, s.x_max, s.y_min, s.y_max)));
}

}  // namespace avsplat::preprocess
