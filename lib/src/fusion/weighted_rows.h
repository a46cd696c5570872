// Weighted sums of scattered float rows, the averaging step of both fusion entry points.
#pragma once

#include <cstddef>
#include <cstdint>

namespace avsplat::fusion_detail {

// Starts fetching a feature row. Each row is read once, so it is fetched non-temporally (x86
// prefetchnta): it does not push the positions, indices and weights out of the outer caches.
inline void prefetch_row(const float* row, std::size_t floats) {
    const char* p = reinterpret_cast<const char*>(row);
    const char* end = p + floats * sizeof(float);
    for (; p < end; p += 64) __builtin_prefetch(p, 0, 0);
    __builtin_prefetch(end - 1, 0, 0);
}

// out[c] = float(inv * sum_k w[k] * rows[ids[k] * width + c]) for c < width, summed in double
// over k in order; returns whether every out[c] is finite. Blocks of 16 channels stay in
// registers across the voxel's samples (the rows stay in L1), so the accumulators are never
// reloaded; each channel is still summed in sample order, whatever the block.
// Built for x86-64-v3 and the baseline (cpu_dispatch.h).
bool weighted_rows(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                   const double* __restrict w, std::size_t n, double inv, float* __restrict out);

}  // namespace avsplat::fusion_detail
