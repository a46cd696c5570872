// The per-frame parameters of the CUDA kernels, built on the host from a Camera and
// RenderOptions: the view parameters by the very function the CPU renderer uses (view_params.h),
// the compositing constants as the CPU renderer rounds its own (render_cpu.cpp).
// Used by render_cuda.cpp and by the tests that run the kernels' bodies on the host.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"
#include "render/shared/view_params.h"
#include "render/cuda/render_frame.h"
#include "render/cuda/kernel_bodies.h"

namespace avsplat::gpu {

/// View parameters for rendering Gaussians of SH degree `sh_degree` from `camera`: the CPU
/// renderer's own (view_params.h).
using preprocess::view_params;

/// The arrays of a host GaussianCloud (on_device false: render_frame uploads them first).
inline GaussianArrays cloud_arrays(const GaussianCloud& cloud) {
    GaussianArrays g;
    g.size = cloud.size();
    g.sh_degree = cloud.sh_degree;
    g.means = cloud.means.data();
    g.scales = cloud.scales.data();
    g.rotations = cloud.rotations.data();
    g.opacities = cloud.opacities.data();
    g.sh = cloud.sh.data();
    g.on_device = false;
    return g;
}

/// Compositing parameters from the options.
template <class T>
BlendParams<T> blend_params(const RenderOptions& options) {
    return BlendParams<T>{T(options.alpha_threshold),
                          T(options.transmittance_stop),
                          {T(options.background[0]), T(options.background[1]), T(options.background[2])}};
}

}  // namespace avsplat::gpu
