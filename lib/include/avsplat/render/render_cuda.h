// The CUDA back end of render(): Gaussians already in GPU memory, and whether a GPU is there.
//
// render(cloud, camera, {.backend = Backend::Cuda}) (render.h) copies a host GaussianCloud to
// the current CUDA device; the overload here reads arrays that are already on the device, e.g.
// the output of a network, without a round trip through the host. Both run the same pipeline
// as the CPU renderer (projection, 16 x 16 tile binning, sort by tile then depth, per-tile
// compositing with early termination) with the same shared maths (projection.h, sh.h,
// tiling.h, blend.h), so their images match the CPU renderer's: in float32 the CUDA kernels are
// compiled without FMA contraction and perform the CPU renderer's operations in its order.
// Results are deterministic: each pixel sums its splats in (depth, index) order, and atomics
// are used only for integer counters.
//
// Both are synchronous: they return when the images are on the host (RenderResult), and they
// run on the current device (cudaSetDevice) in its legacy default stream, which waits for work
// that other blocking streams queued before the call. Device memory is allocated per call with
// cudaMalloc (never managed memory) and freed before returning.
//
// Errors: avsplat::DeviceError when avsplat was built without CUDA, when no CUDA device or
// driver is usable ("no CUDA device: <CUDA error string>"), when an allocation or a kernel
// fails (the message names the step and gives the CUDA error string), or when a frame exceeds
// 2^31 - 1 (splat, tile) instances. A DeviceError leaves the process usable except after a
// kernel fault, which CUDA makes sticky for the process.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/device_gaussians.h"
#include "avsplat/render/render.h"

#include <cstddef>

namespace avsplat {

/// Renders device-resident Gaussians from `camera` on the current CUDA device; the outputs and
/// statistics are those of render() (render.h). `options.backend` must be Backend::Cuda.
/// The values are checked on the device with the rules of avsplat::validate.
/// Throws std::invalid_argument for a bad option or camera (naming it), an SH degree outside
/// 0..3, a null array when size > 0, a pointer that is not device (or managed) memory of the
/// current device ("DeviceGaussians.means: not device memory of device 0"), 2^32 Gaussians or
/// more, or an invalid value ("DeviceGaussians.scales[12]: negative scale", the first bad
/// Gaussian); avsplat::DeviceError as listed in the header comment.
RenderResult render(const DeviceGaussians& gaussians, const Camera& camera,
                    const RenderOptions& options);

/// Number of CUDA devices that render() with Backend::Cuda can use: 0 when avsplat was built
/// without CUDA, or when no driver or device is present. Never throws.
int cuda_device_count() noexcept;

/// An owning copy of a GaussianCloud in the memory of the current CUDA device, freed by the
/// destructor; view() is the input of render(const DeviceGaussians&, ...). Not copyable or
/// movable. Throws avsplat::DeviceError when avsplat was built without CUDA, when no device is
/// usable, or when an allocation or copy fails (nothing stays allocated then).
class DeviceGaussianCloud {
public:
    explicit DeviceGaussianCloud(const GaussianCloud& cloud);
    ~DeviceGaussianCloud();
    DeviceGaussianCloud(const DeviceGaussianCloud&) = delete;
    DeviceGaussianCloud& operator=(const DeviceGaussianCloud&) = delete;

    /// The device arrays, valid while this object lives.
    const DeviceGaussians& view() const { return view_; }

private:
    void release() noexcept;
    DeviceGaussians view_;
    float* buffers_[5] = {nullptr, nullptr, nullptr, nullptr, nullptr};
};

}  // namespace avsplat
