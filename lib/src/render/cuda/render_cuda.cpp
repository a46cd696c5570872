// Host entry points of the CUDA renderer: render() for host clouds (through render.cpp's
// dispatch) and for device arrays, and cuda_device_count(). They turn the camera and options
// into the plain parameters of kernel_bodies.h, exactly as the CPU renderer does, and call the CUDA
// code in render_cuda.cu. Compiled in every build; without CUDA they report that the renderer
// is not built in.
#include "render/cuda/render_cuda_entry.h"

#include "avsplat/core/error.h"
#include "avsplat/render/render_cuda.h"
#include "render/cuda/render_frame.h"
#include "render/cuda/kernel_params.h"

#include <chrono>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

namespace {

#ifdef AVSPLAT_WITH_CUDA

template <class T>
RenderResult run(const gpu::GaussianArrays& g, const Camera& camera, const RenderOptions& options) {
    const gpu::FramePlan plan = gpu::plan_frame(camera.width, camera.height);
    RenderResult out;
    out.width = camera.width;
    out.height = camera.height;
    out.color.resize(3 * plan.pixels);
    out.alpha.resize(plan.pixels);
    out.depth.resize(plan.pixels);
    out.contributors.resize(plan.pixels);
    const gpu::FrameOutput images{out.color.data(), out.alpha.data(), out.depth.data(),
                                  out.contributors.data()};
    const gpu::FrameStats s = gpu::render_frame<T>(g, gpu::view_params<T>(camera, options, g.sh_degree),
                                                   gpu::blend_params<T>(options), plan, images);
    RenderStats& st = out.stats;
    st.gaussians = std::size_t(g.size);
    st.visible = std::size_t(s.visible);
    st.tile_instances = std::size_t(s.tile_instances);
    st.blends = s.blends;
    st.contributions = s.contributions;
    st.threads = 1;  // host threads; the GPU's parallelism is not counted here
    st.seconds_projection = s.seconds_projection;
    st.seconds_sorting = s.seconds_sorting;
    st.seconds_blending = s.seconds_blending;
    return out;
}

RenderResult run_precision(const gpu::GaussianArrays& g, const Camera& camera,
                           const RenderOptions& options) {
    return options.precision == Precision::Float64 ? run<double>(g, camera, options)
                                                   : run<float>(g, camera, options);
}

#else

[[noreturn]] void not_built() {
    throw DeviceError("render: avsplat was built without the CUDA renderer (configure with "
                      "AVSPLAT_WITH_CUDA=ON and a CUDA compiler); use backend Cpu");
}

#endif

}  // namespace

namespace detail {

RenderResult render_cuda(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& options) {
#ifdef AVSPLAT_WITH_CUDA
    gpu::require_device();
    return run_precision(gpu::cloud_arrays(cloud), camera, options);
#else
    (void)cloud;
    (void)camera;
    (void)options;
    not_built();
#endif
}

}  // namespace detail

RenderResult render(const DeviceGaussians& gaussians, const Camera& camera, const RenderOptions& options) {
    const auto t0 = std::chrono::steady_clock::now();
    if (options.backend != Backend::Cuda)
        throw std::invalid_argument("RenderOptions.backend: device arrays are rendered with Backend::Cuda");
    detail::check_render_options(options);
    if (options.gaussian_contributions)
        throw DeviceError("RenderOptions.gaussian_contributions: per-Gaussian contributions are computed by the "
                          "CPU back end only; render a GaussianCloud with Backend::Cpu");
    camera.validate();
    if (gaussians.sh_degree < 0 || gaussians.sh_degree > kMaxShDegree)
        throw std::invalid_argument("DeviceGaussians.sh_degree: " + std::to_string(gaussians.sh_degree) +
                                    " is not a supported SH degree (0..3)");
    if (gaussians.size > std::size_t(std::numeric_limits<std::uint32_t>::max()))
        throw std::invalid_argument("render: " + std::to_string(gaussians.size) +
                                    " Gaussians; at most 2^32 - 1 are supported");
#ifdef AVSPLAT_WITH_CUDA
    gpu::require_device();
    const struct {
        const char* name;
        const float* p;
    } arrays[] = {{"means", gaussians.means},
                  {"scales", gaussians.scales},
                  {"rotations", gaussians.rotations},
                  {"opacities", gaussians.opacities},
                  {"sh", gaussians.sh}};
    if (gaussians.size > 0) {
        for (const auto& a : arrays) {
            if (a.p == nullptr)
                throw std::invalid_argument(std::string("DeviceGaussians.") + a.name +
                                            ": null pointer for " + std::to_string(gaussians.size) +
                                            " Gaussians");
            gpu::check_device_pointer(a.p, a.name);
        }
    }
    gpu::GaussianArrays g;
    static_cast<DeviceGaussians&>(g) = gaussians;
    g.on_device = true;
    gpu::validate_on_device(g);
    RenderResult result = run_precision(g, camera, options);
    result.stats.seconds_total =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return result;
#else
    (void)t0;
    not_built();
#endif
}

DeviceGaussianCloud::DeviceGaussianCloud(const GaussianCloud& cloud) {
#ifdef AVSPLAT_WITH_CUDA
    view_.size = cloud.size();
    view_.sh_degree = cloud.sh_degree;
    const std::vector<float>* arrays[5] = {&cloud.means, &cloud.scales, &cloud.rotations,
                                           &cloud.opacities, &cloud.sh};
    const char* names[5] = {"uploading means", "uploading scales", "uploading rotations",
                            "uploading opacities", "uploading sh"};
    try {
        for (int i = 0; i < 5; ++i)
            buffers_[i] = gpu::upload_floats(arrays[i]->data(), arrays[i]->size(), names[i]);
    } catch (...) {
        release();
        throw;
    }
    view_.means = buffers_[0];
    view_.scales = buffers_[1];
    view_.rotations = buffers_[2];
    view_.opacities = buffers_[3];
    view_.sh = buffers_[4];
#else
    (void)cloud;
    throw DeviceError("DeviceGaussianCloud: avsplat was built without the CUDA renderer (configure "
                      "with AVSPLAT_WITH_CUDA=ON and a CUDA compiler)");
#endif
}

DeviceGaussianCloud::~DeviceGaussianCloud() { release(); }

void DeviceGaussianCloud::release() noexcept {
#ifdef AVSPLAT_WITH_CUDA
    for (float*& p : buffers_) {
        gpu::free_device(p);
        p = nullptr;
    }
#endif
}

int cuda_device_count() noexcept {
#ifdef AVSPLAT_WITH_CUDA
    return gpu::device_count();
#else
    return 0;
#endif
}

}  // namespace avsplat
