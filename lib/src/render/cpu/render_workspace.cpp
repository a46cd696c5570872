// RenderWorkspace (render.h): the owner of the CPU renderer's reusable scratch buffers.
#include "render/cpu/render_workspace.h"

namespace avsplat {

RenderWorkspace::RenderWorkspace() : buffers_(std::make_unique<Buffers>()) {}
RenderWorkspace::~RenderWorkspace() = default;
RenderWorkspace::RenderWorkspace(RenderWorkspace&&) noexcept = default;
RenderWorkspace& RenderWorkspace::operator=(RenderWorkspace&&) noexcept = default;

std::size_t RenderWorkspace::bytes() const { return buffers_ ? buffers_->bytes() : 0; }

void RenderWorkspace::release() {
    if (buffers_) buffers_->release();
}

RenderWorkspace::Buffers& RenderWorkspace::buffers() {
    // A moved-from workspace gets fresh buffers, so it stays usable.
    if (!buffers_) buffers_ = std::make_unique<Buffers>();
    return *buffers_;
}

}  // namespace avsplat
