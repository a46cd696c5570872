// The CPU back end of render(): declared here for render.cpp's dispatch, defined and
// instantiated for float and double in render_cpu.cpp.
#pragma once

#include "avsplat/render/render.h"

namespace avsplat::detail {

/// Renders with scalar T (float or double). Expects a validated cloud, camera and options and
/// fewer than 2^32 Gaussians (render() checks them); fills everything but stats.seconds_total.
/// Its scratch memory comes from `buffers` (render_workspace.h), which it may grow.
template <class T>
RenderResult render_cpu(const GaussianCloud& cloud, const Camera& camera,
                        const RenderOptions& options, RenderWorkspace::Buffers& buffers);

extern template RenderResult render_cpu<float>(const GaussianCloud&, const Camera&,
                                               const RenderOptions&, RenderWorkspace::Buffers&);
extern template RenderResult render_cpu<double>(const GaussianCloud&, const Camera&,
                                                const RenderOptions&, RenderWorkspace::Buffers&);

}  // namespace avsplat::detail
