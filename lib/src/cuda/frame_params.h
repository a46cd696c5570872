// The per-frame parameters of the CUDA kernels, built on the host from a Camera and
// RenderOptions exactly as the CPU renderer builds its own (render_cpu.cpp): the view rotation
// and translation stay in double, the rotation, intrinsics and thresholds are rounded to T.
// Used by render_cuda.cpp and by the tests that run the kernels' bodies on the host.
#pragma once

#include "avsplat/camera.h"
#include "avsplat/render.h"
#include "pipeline.h"

namespace avsplat::gpu {

/// View parameters for rendering Gaussians of SH degree `sh_degree` from `camera`.
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

/// Compositing parameters from the options.
template <class T>
BlendParams<T> blend_params(const RenderOptions& options) {
    return BlendParams<T>{T(options.alpha_threshold),
                          T(options.transmittance_stop),
                          {T(options.background[0]), T(options.background[1]), T(options.background[2])}};
}

}  // namespace avsplat::gpu
