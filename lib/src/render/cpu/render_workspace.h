// The scratch buffers of the CPU renderer that a RenderWorkspace (render.h) keeps between renders:
// uninitialised, 64-byte aligned, grown on demand and never shrunk until release(); and the
// images of results given back with RenderWorkspace::recycle.
#pragma once

#include "avsplat/render/render.h"
#include "common/huge_pages.h"

#include <atomic>
#include <cstdint>
#include <utility>
#include <vector>
#include <cstddef>
#include <cstdlib>
#include <new>
#include <type_traits>

namespace avsplat {

namespace detail {

/// Raw memory for n values of a trivial type U, reused while it is large enough. get() leaves
/// the contents unspecified (whatever the last user wrote, or fresh pages): callers write
/// before they read.
class ScratchBuffer {
public:
    ScratchBuffer() = default;
    ScratchBuffer(const ScratchBuffer&) = delete;
    ScratchBuffer& operator=(const ScratchBuffer&) = delete;
    ~ScratchBuffer() { std::free(data_); }

    /// With `reuse` false (a buffer for one render only) the allocation has no headroom.
    template <class U>
    U* get(std::size_t n, bool reuse = true) {
        static_assert(std::is_trivially_default_constructible_v<U> && std::is_trivially_destructible_v<U>,
                      "ScratchBuffer holds trivial types only");
        static_assert(alignof(U) <= kAlign, "ScratchBuffer aligns to 64 bytes");
        if (n > kMaxBytes / sizeof(U)) throw std::bad_alloc();
        const std::size_t need = n * sizeof(U);
        if (need > bytes_ || data_ == nullptr) {
            // An eighth of headroom, so that frames of slightly growing size do not reallocate.
            std::size_t want = reuse ? need + need / 8 : need;
            want = (want + kAlign - 1) / kAlign * kAlign;
            if (want == 0) want = kAlign;
            // Buffers of 4 MiB and more start on a 2 MiB boundary and ask for transparent huge
            // pages: the records are gathered and the tile lists scattered at random across them,
            // which with 4 KiB pages misses the TLB on nearly every access; and a fresh buffer
            // takes one page fault per 2 MiB instead of one per 4 KiB (the faults, not only the
            // clearing, cost on a VM).
            const bool huge = want >= kHugeMin;
            if (huge) want = (want + kHuge - 1) / kHuge * kHuge;
            void* fresh = std::aligned_alloc(huge ? kHuge : kAlign, want);
            if (fresh != nullptr && huge) advise_huge_pages(fresh, want);
            if (fresh == nullptr) throw std::bad_alloc();
            std::free(data_);
            data_ = fresh;
            bytes_ = want;
        }
        return static_cast<U*>(data_);
    }
    std::size_t bytes() const { return bytes_; }
    void release() {
        std::free(data_);
        data_ = nullptr;
        bytes_ = 0;
    }

private:
    static constexpr std::size_t kAlign = 64;
    static constexpr std::size_t kHuge = std::size_t(1) << 21;
    static constexpr std::size_t kHugeMin = std::size_t(1) << 22;
    static constexpr std::size_t kMaxBytes = std::size_t(1) << 62;
    void* data_ = nullptr;
    std::size_t bytes_ = 0;
};

}  // namespace detail

/// What render_cpu.cpp keeps in a workspace; each buffer's use is documented there.
struct RenderWorkspace::Buffers {
    detail::ScratchBuffer records;  ///< one record per Gaussian, written by projection
    detail::ScratchBuffer keys;     ///< one sort key per Gaussian
    detail::ScratchBuffer order;    ///< the visible keys, then sorted
    detail::ScratchBuffer order_tmp;
    detail::ScratchBuffer sorted;   ///< the visible records in depth order
    detail::ScratchBuffer rects;    ///< their tile rectangles
    detail::ScratchBuffer lists;    ///< the tile lists, positions in `sorted`
    detail::ScratchBuffer offsets;  ///< tile list starts
    detail::ScratchBuffer counts;   ///< per thread and tile (binning), per thread (compaction)
    /// Images given back by RenderWorkspace::recycle, for the next result.
    std::vector<float> color, alpha, depth;
    std::vector<std::int32_t> contributors;
    std::atomic<bool> in_use{false};
    /// False for the workspace of a single render() call (ScratchBuffer::get's `reuse`: no headroom).
    bool reuse = true;

    /// Moves the recycled images (if any) into `out`.
    void take_images(RenderResult& out) {
        out.color = std::move(color);
        out.alpha = std::move(alpha);
        out.depth = std::move(depth);
        out.contributors = std::move(contributors);
        color.clear();
        alpha.clear();
        depth.clear();
        contributors.clear();
    }

    std::size_t bytes() const {
        return records.bytes() + keys.bytes() + order.bytes() + order_tmp.bytes() + sorted.bytes() + rects.bytes() +
               lists.bytes() + offsets.bytes() + counts.bytes() +
               (color.capacity() + alpha.capacity() + depth.capacity()) * sizeof(float) +
               contributors.capacity() * sizeof(std::int32_t);
    }
    void release() {
        for (detail::ScratchBuffer* b :
             {&records, &keys, &order, &order_tmp, &sorted, &rects, &lists, &offsets, &counts})
            b->release();
        std::vector<float>().swap(color);
        std::vector<float>().swap(alpha);
        std::vector<float>().swap(depth);
        std::vector<std::int32_t>().swap(contributors);
    }
};

}  // namespace avsplat
