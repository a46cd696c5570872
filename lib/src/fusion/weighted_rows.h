// Weighted sums of scattered float rows, the averaging step of both fusion entry points.
#pragma once

#include <cstddef>
#include <cstdint>

namespace avsplat::fusion_detail {

// Starts fetching a feature row into the L2 cache (x86 prefetcht1). The rows are read once, at
// random, some twenty rows after this call: fetched into L1 (prefetcht0) they would push out
// what the loop reads meanwhile, fetched non-temporally (prefetchnta) they are dropped before
// use (docs/benchmarks/fusion.md: a bare 2M-row gather takes 50 ms with this hint, 67 with
// prefetchnta, 70 with prefetcht0, 94 without prefetching, one thread).
inline void prefetch_row(const float* row, std::size_t floats) {
    const char* p = reinterpret_cast<const char*>(row);
    const char* end = p + floats * sizeof(float);
    for (; p < end; p += 64) __builtin_prefetch(p, 0, 2);
    __builtin_prefetch(end - 1, 0, 2);
}

// out[c] = float(inv * sum_k w[k] * rows[ids[k] * width + c]) for c < width, summed in double
// over k in order; returns whether every out[c] is finite. Blocks of up to 32 channels (56 in the
// AVX2 version) stay in vector registers across the voxel's samples (the rows stay in L1), so the
// accumulators are never reloaded; each channel is still summed in sample order, whatever the
// block, so the result does not depend on the blocking.
// Runs weighted_rows_avx2 where the CPU has AVX2, else weighted_rows_baseline: both do the same
// multiplies and adds in the same order (no FMA), so they give the same bits.
bool weighted_rows(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                   const double* __restrict w, std::size_t n, double inv, float* __restrict out);

// weighted_rows in portable code (GCC's vector extension; SSE2 on x86-64).
bool weighted_rows_baseline(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                            const double* __restrict w, std::size_t n, double inv, float* __restrict out);

// weighted_rows in AVX2 intrinsics: each four channels are loaded and widened by one vcvtps2pd
// (GCC 12 splits the vector extension's float-to-double conversion into halves through the
// stack). Call only where avx2_available(); without the x86-64 GCC build it is the baseline.
bool weighted_rows_avx2(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                        const double* __restrict w, std::size_t n, double inv, float* __restrict out);

// Whether this CPU runs weighted_rows_avx2.
bool avx2_available();

}  // namespace avsplat::fusion_detail
