#include "common/populate_pages.h"

#include <algorithm>
#include <cstdint>
#ifdef __linux__
#include <sys/mman.h>
#endif

namespace avsplat {

void populate_pages(const std::vector<ByteRange>& ranges) {
#if defined(__linux__) && defined(MADV_POPULATE_WRITE)
    constexpr std::uintptr_t kPage = 4096;
    constexpr std::uintptr_t kChunk = std::uintptr_t(1) << 21;
    struct Chunk {
        std::uintptr_t begin, end;
    };
    std::vector<Chunk> chunks;
    std::size_t total = 0;
    for (const ByteRange& r : ranges) {
        // Whole pages only: the bytes around the range may belong to other objects.
        const std::uintptr_t b = (reinterpret_cast<std::uintptr_t>(r.data) + kPage - 1) & ~(kPage - 1);
        const std::uintptr_t e = (reinterpret_cast<std::uintptr_t>(r.data) + r.bytes) & ~(kPage - 1);
        if (r.data == nullptr || e <= b) continue;
        total += e - b;
        // Chunk borders on 2 MiB boundaries, so that no huge page is split between two threads.
        for (std::uintptr_t c = b; c < e;) {
            const std::uintptr_t next = std::min<std::uintptr_t>(e, (c & ~(kChunk - 1)) + kChunk);
            chunks.push_back({c, next});
            c = next;
        }
    }
    if (total < 4 * kChunk) return;
    // A failure (EINVAL from a kernel without MADV_POPULATE_WRITE, ENOMEM) leaves the pages to be
    // faulted in by their first write, as without this call; memory is not reserved here.
#pragma omp parallel for schedule(static)
    for (long long k = 0; k < static_cast<long long>(chunks.size()); ++k) {
        const Chunk& c = chunks[static_cast<std::size_t>(k)];
        ::madvise(reinterpret_cast<void*>(c.begin), c.end - c.begin, MADV_POPULATE_WRITE);
    }
#else
    (void)ranges;
#endif
}

}  // namespace avsplat
