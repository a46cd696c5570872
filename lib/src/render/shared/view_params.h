// Host-side construction of the per-frame view parameters of project_and_shade.h from a Camera and
// RenderOptions, shared by the CPU renderer (render_cpu.cpp) and the CUDA host code
// (cuda/kernel_params.h): the view, the intrinsics, near/far and the thresholds stay in double
// for both precisions, since the projection and its culling run in double (projection.h,
// "Precision"). Kept apart from project_and_shade.h because it needs Camera (Eigen), which nvcc must
// not parse.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/render/render.h"
#include "render/shared/project_and_shade.h"

namespace avsplat::preprocess {

/// View parameters for rendering Gaussians of SH degree `sh_degree` (0..3) from `camera` with
/// `options` (near/far from the camera; low_pass, extent_sigma, alpha_threshold and
/// antialiased from the options). Expects a validated camera and options (render() checks).
template <class T>
ViewParams<T> view_params(const Camera& camera, const RenderOptions& options, int sh_degree) {
    ViewParams<T> v;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) v.R[3 * r + c] = camera.world_to_camera(r, c);
        v.t[r] = camera.world_to_camera(r, 3);
    }
    v.K = projection::Intrinsics<double>{camera.fx, camera.fy, camera.cx, camera.cy, camera.width,
                                         camera.height};
    v.proj = projection::ProjectionParams{camera.near, camera.far, double(options.low_pass),
                                          double(options.extent_sigma),
                                          double(options.alpha_threshold), options.antialiased};
    v.sh_degree = sh_degree;
    return v;
}

}  // namespace avsplat::preprocess
