// DeviceGaussians: Gaussian arrays in GPU memory, the input of render(DeviceGaussians, ...)
// (render_cuda.h). A header of its own, free of Eigen and CUDA headers, because the CUDA
// renderer's glue (compiled by nvcc, which must not parse Eigen) describes its inputs with the
// same struct.
#pragma once

#include <cstddef>

namespace avsplat {

/// Gaussians whose arrays live in the memory of the current CUDA device, with the layout of
/// GaussianCloud (row-major, contiguous float32, N = size):
///   means      N x 3                      world positions
///   scales     N x 3                      linear axis lengths, >= 0
///   rotations  N x 4                      quaternions (w, x, y, z), not zero
///   opacities  N                          in [0, 1]
///   sh         N x (sh_degree + 1)^2 x 3  SH coefficients, degree 0 first
/// The pointers are not owned; they must stay valid, and unchanged, during the call.
struct DeviceGaussians {
    std::size_t size = 0;
    int sh_degree = 0;
    const float* means = nullptr;
    const float* scales = nullptr;
    const float* rotations = nullptr;
    const float* opacities = nullptr;
    const float* sh = nullptr;
};

}  // namespace avsplat
