// render(): input checks and the dispatch to a back end.
#include "avsplat/render/render.h"

#include "avsplat/core/error.h"
#include "render/cuda/render_cuda_entry.h"
#include "render/cpu/render_cpu.h"
#include "render/cpu/render_workspace.h"
#include "render/shared/tiling.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace detail {

void check_render_options(const RenderOptions& o) {
    auto fail = [](const std::string& what) { throw std::invalid_argument("RenderOptions." + what); };
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(o.background[c])) fail("background[" + std::to_string(c) + "]: must be finite");
    if (!(o.low_pass >= 0.0f) || !std::isfinite(o.low_pass)) fail("low_pass: must be finite and >= 0");
    if (!(o.alpha_threshold > 0.0f && o.alpha_threshold < 1.0f)) fail("alpha_threshold: must be in (0, 1)");
    if (!(o.transmittance_stop > 0.0f && o.transmittance_stop < 1.0f))
        fail("transmittance_stop: must be in (0, 1)");
    if (!(o.extent_sigma > 0.0f) || !std::isfinite(o.extent_sigma)) fail("extent_sigma: must be finite and > 0");
}

}  // namespace detail

std::string RenderStats::summary() const {
    std::ostringstream os;
    os.precision(3);
    os << "visible " << visible << "/" << gaussians << ", " << tile_instances << " tile instances, "
       << double(blends) << " blends, " << double(contributions) << " contributions, "
       << seconds_total * 1e3 << " ms (projection " << seconds_projection * 1e3 << ", sorting "
       << seconds_sorting * 1e3 << ", blending " << seconds_blending * 1e3 << "), " << threads
       << (threads == 1 ? " thread" : " threads");
    return os.str();
}

RenderResult render(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& options) {
    RenderWorkspace workspace;  // this call's buffers only
    workspace.buffers().reuse = false;
    return render(cloud, camera, options, workspace);
}

RenderResult render(const GaussianCloud& cloud, const Camera& camera, const RenderOptions& options,
                    RenderWorkspace& workspace) {
    const auto t0 = std::chrono::steady_clock::now();
    detail::check_render_options(options);
    camera.validate();
    validate(cloud);
    // Tile coordinates and counts are int and tile ids 32-bit (tiling.h): refuse image sizes
    // whose arithmetic would overflow, before anything is allocated. Sizes below this that do not
    // fit in memory give std::bad_alloc (MemoryError in Python).
    constexpr int kMaxSide = 1 << 24;
    if (camera.width > kMaxSide || camera.height > kMaxSide)
        throw std::invalid_argument("render: camera.width x camera.height = " + std::to_string(camera.width) + " x " +
                                    std::to_string(camera.height) + ": at most 2^24 pixels per side are supported");
    const std::uint64_t tiles = std::uint64_t(tiling::tiles_along(camera.width)) *
                                std::uint64_t(tiling::tiles_along(camera.height));
    if (tiles > std::uint64_t(std::numeric_limits<int>::max()))
        throw std::invalid_argument("render: camera.width x camera.height = " + std::to_string(camera.width) + " x " +
                                    std::to_string(camera.height) + " needs " + std::to_string(tiles) +
                                    " tiles of 16 x 16; at most 2^31 - 1 are supported");
    // Gaussian indices are 32-bit in the sort keys (tiling.h).
    if (cloud.size() > std::size_t(std::numeric_limits<std::uint32_t>::max()))
        throw std::invalid_argument("render: the cloud has " + std::to_string(cloud.size()) +
                                    " Gaussians; at most 2^32 - 1 are supported");

    RenderResult result;
    switch (options.backend) {
    case Backend::Cpu: {
        RenderWorkspace::Buffers& buffers = workspace.buffers();
        if (buffers.in_use.exchange(true))
            throw std::logic_error("render: the RenderWorkspace is in use by another render; give each thread its own");
        struct Release {
            std::atomic<bool>& flag;
            ~Release() { flag.store(false); }
        } release{buffers.in_use};
        result = options.precision == Precision::Float64
                     ? detail::render_cpu<double>(cloud, camera, options, buffers)
                     : detail::render_cpu<float>(cloud, camera, options, buffers);
        break;
    }
    case Backend::Cuda:
        if (options.gaussian_contributions)
            throw DeviceError("RenderOptions.gaussian_contributions: per-Gaussian contributions are computed by "
                              "the CPU back end only; render with Backend::Cpu");
        // CUDA back end: see lib/src/cuda/ (throws DeviceError in a build without CUDA).
        result = detail::render_cuda(cloud, camera, options);
        break;
    }
    result.stats.seconds_total =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return result;
}

}  // namespace avsplat
