// Faulting in the pages of fresh output buffers on every thread, before one thread first writes
// them.
#pragma once

#include <cstddef>
#include <vector>

namespace avsplat {

/// A buffer's address and size in bytes.
struct ByteRange {
    const void* data;
    std::size_t bytes;
};

/// Has the kernel fault in (Linux: madvise MADV_POPULATE_WRITE) the whole pages inside each
/// range, 2 MiB at a time split over the OpenMP threads, so that the kernel's zeroing of fresh
/// memory runs on every core rather than on the one thread that first writes it (as
/// std::vector::resize does when it value-initialises). Ranges are typically reserved capacity
/// not yet in use. The contents never change: a fresh page is zero, a present one is left as it
/// is. Worth it only for large buffers: ranges of less than 8 MiB in all are left alone. A no-op
/// where the kernel does not support it (before Linux 5.14) and outside Linux.
void populate_pages(const std::vector<ByteRange>& ranges);

}  // namespace avsplat
