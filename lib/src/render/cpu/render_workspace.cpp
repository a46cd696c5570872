// RenderWorkspace (render.h): the owner of the CPU renderer's reusable scratch buffers.
#include "render/cpu/render_workspace.h"

#include <stdexcept>

namespace avsplat {

RenderWorkspace::RenderWorkspace() : buffers_(std::make_unique<Buffers>()) {}
RenderWorkspace::~RenderWorkspace() = default;
RenderWorkspace::RenderWorkspace(RenderWorkspace&&) noexcept = default;
RenderWorkspace& RenderWorkspace::operator=(RenderWorkspace&&) noexcept = default;

std::size_t RenderWorkspace::bytes() const { return buffers_ ? buffers_->bytes() : 0; }

void RenderWorkspace::release() {
    if (!buffers_) return;
    // Freeing the buffers under a running render (another thread's) would pull its memory away.
    if (buffers_->in_use.exchange(true))
        throw std::logic_error("RenderWorkspace::release: the workspace is in use by a render; release it after "
                               "the render returns");
    buffers_->release();
    buffers_->in_use.store(false);
}

void RenderWorkspace::recycle(RenderResult&& result) {
    Buffers& b = buffers();
    if (b.in_use.exchange(true)) return;  // a render is using the workspace: leave it alone
    // The largest of each, so that alternating sizes settle on the larger memory.
    auto keep = [](auto& mine, auto& theirs) {
        if (theirs.capacity() > mine.capacity()) mine = std::move(theirs);
    };
    keep(b.color, result.color);
    keep(b.alpha, result.alpha);
    keep(b.depth, result.depth);
    keep(b.contributors, result.contributors);
    b.in_use.store(false);
}

RenderWorkspace::Buffers& RenderWorkspace::buffers() {
    // A moved-from workspace gets fresh buffers, so it stays usable.
    if (!buffers_) buffers_ = std::make_unique<Buffers>();
    return *buffers_;
}

}  // namespace avsplat
