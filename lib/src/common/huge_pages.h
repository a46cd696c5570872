// Transparent huge pages for the large buffers of voxel fusion (grid build, fused outputs).
#pragma once

#include <cstddef>
#include <vector>

namespace avsplat {

/// Asks the kernel (Linux: madvise MADV_HUGEPAGE) to back the 2 MiB-aligned part of a buffer of
/// at least 4 MiB with transparent huge pages, before it is first touched: filling it then
/// faults in 2 MiB pages instead of 4 KiB ones (an 8 MB buffer, 2M int32 sample ids, took about
/// 2,000 page faults per fusion call without it). A no-op elsewhere or for smaller buffers; it
/// never changes the buffer's contents.
void advise_huge_pages(const void* data, std::size_t bytes);

/// Reserves room for n elements in an empty vector and advises huge pages for it.
template <class T>
void reserve_huge(std::vector<T>& v, std::size_t n) {
    if (v.capacity() >= n) return;
    v.reserve(n);
    advise_huge_pages(v.data(), n * sizeof(T));
}

}  // namespace avsplat
