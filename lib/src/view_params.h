// Host-side construction of the per-frame view parameters of preprocess.h from a Camera and
// RenderOptions, shared by the CPU renderer (render_cpu.cpp) and the CUDA host code
// (cuda/frame_params.h): the view rotation and translation stay in double; the rotation used
// for covariances, the intrinsics and the thresholds are rounded to T. Kept apart from
// preprocess.h because it needs Camera (Eigen), which nvcc must not parse.
#pragma once

#include "avsplat/camera.h"
#include "avsplat/render.h"
#include "preprocess.h"

namespace avsplat::preprocess {

/// View parameters for rendering Gaussians of SH degree `sh_degree` (0..3) from `camera` with
/// `options` (near/far from the camera; low_pass, extent_sigma, alpha_threshold and
/// antialiased from the options). Expects a validated camera and options (render() checks).
template <class T>
ViewParams<T> view_params(const Camera& camera, const RenderOptions& options, int sh_degree) {
    ViewParams<T> v;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
            v.R[3 * r + c] = camera.world_to_camera(r, c);
            v.R_t[3 * r + c] = T(v.R[3 * r + c]);
        }
        v.t[r] = camera.world_to_camera(r, 3);
    }
    v.K = projection::Intrinsics<T>{T(camera.fx), T(camera.fy), T(camera.cx), T(camera.cy),
                                    camera.width, camera.height};
    v.proj = projection::ProjectionParams<T>{T(camera.near), T(camera.far), T(options.low_pass),
                                             T(options.extent_sigma), T(options.alpha_threshold),
                                             options.antialiased};
    v.sh_degree = sh_degree;
    return v;
}

}  // namespace avsplat::preprocess
