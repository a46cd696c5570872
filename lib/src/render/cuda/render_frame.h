// The interface between the host entry points (render_cuda.cpp, compiled by the C++ compiler:
// camera and options to plain parameters, results to RenderResult) and the CUDA code
// (render_cuda.cu, compiled by nvcc). Nothing here includes Eigen or CUDA headers, so nvcc never
// parses Eigen and the C++ compiler never parses CUDA.
//
// Declared for every build; defined only when AVSPLAT_WITH_CUDA (the .cu file is compiled).
#pragma once

#include "avsplat/render/device_gaussians.h"
#include "render/cuda/launch_plan.h"
#include "render/cuda/kernel_bodies.h"

#include <cstddef>
#include <cstdint>

namespace avsplat::gpu {

/// Gaussian arrays with GaussianCloud's layout (the fields of DeviceGaussians), in host memory
/// or in device memory.
struct GaussianArrays : DeviceGaussians {
    bool on_device = false;  ///< false: host arrays, copied to the device first
};

/// Host buffers the frame's images are written to (sizes from the FramePlan: 3 x pixels floats
/// for color, pixels for the others).
struct FrameOutput {
    float* color = nullptr;
    float* alpha = nullptr;
    float* depth = nullptr;
    std::int32_t* contributors = nullptr;
};

/// RenderStats' counters and stage times, as the CUDA path measures them: each stage time ends
/// with a stream synchronisation; uploads of host arrays and allocations before projection are
/// counted in none of them (only in the caller's total).
struct FrameStats {
    std::uint64_t visible = 0;
    std::uint64_t tile_instances = 0;
    std::uint64_t blends = 0;
    std::uint64_t contributions = 0;
    double seconds_projection = 0.0;  ///< projection, culling and SH colour kernel
    double seconds_sorting = 0.0;     ///< scan, key emission, radix sort, tile ranges
    double seconds_blending = 0.0;    ///< compositing kernel and copying the images to the host
};

/// Throws avsplat::DeviceError("no CUDA device: <CUDA error string>") when no device is usable.
void require_device();

/// Number of usable devices, 0 on any error.
int device_count() noexcept;

/// Throws std::invalid_argument ("DeviceGaussians.<field>: not device memory of device D")
/// when `ptr` is not device or managed memory of the current device.
void check_device_pointer(const void* ptr, const char* field);

/// Checks device arrays with the rules of avsplat::validate on the device; throws
/// std::invalid_argument with invalid_message() for the first bad Gaussian.
void validate_on_device(const GaussianArrays& g);

/// Copies n floats from host memory to a new allocation on the current device (at least one
/// float is allocated, so the pointer is never null). Throws avsplat::DeviceError naming `what`.
float* upload_floats(const float* host, std::size_t n, const char* what);

/// Frees memory from upload_floats; null is ignored.
void free_device(void* ptr) noexcept;

/// Renders one frame (inputs already checked). Defined for T = float and double.
template <class T>
FrameStats render_frame(const GaussianArrays& g, const ViewParams<T>& view,
                        const BlendParams<T>& blend, const FramePlan& plan, const FrameOutput& out);

}  // namespace avsplat::gpu
