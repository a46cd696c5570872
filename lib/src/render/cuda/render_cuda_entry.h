// What render.cpp and the CUDA entry points (render_cuda.cpp) need from each other.
#pragma once

#include "avsplat/render/render.h"

namespace avsplat::detail {

/// The CUDA back end of render() for a host cloud: copies it to the current device and renders
/// there. Expects what render() has checked (valid cloud, camera and options, fewer than 2^32
/// Gaussians); fills everything but stats.seconds_total. Throws avsplat::DeviceError when
/// avsplat was built without CUDA, when no device is usable ("no CUDA device: ...") or when a
/// CUDA call fails. Defined in render_cuda.cpp.
RenderResult render_cuda(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& options);

/// Throws std::invalid_argument naming the first bad field of `options` (render()'s checks).
/// Defined in render.cpp, shared with render(const DeviceGaussians&, ...).
void check_render_options(const RenderOptions& options);

}  // namespace avsplat::detail
