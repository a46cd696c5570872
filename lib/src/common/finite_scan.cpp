#include "common/finite_scan.h"

#include "common/cpu_dispatch.h"
#include "common/parallel.h"

#include <algorithm>

namespace avsplat::detail {

namespace {

AVSPLAT_CLONES_V3 bool chunk_non_finite(const float* p, std::size_t n) { return any_non_finite(p, n); }

}  // namespace

bool any_non_finite_parallel(const float* p, std::size_t n) {
    constexpr std::size_t kChunk = 16384;  // floats: 64 KiB
    const std::int64_t chunks = std::int64_t((n + kChunk - 1) / kChunk);
    int bad = 0;
#pragma omp parallel for schedule(static) reduction(| : bad) num_threads(threads_for(n / 64))
    for (std::int64_t ci = 0; ci < chunks; ++ci) {
        const std::size_t b = std::size_t(ci) * kChunk;
        bad |= int(chunk_non_finite(p + b, std::min(n, b + kChunk) - b));
    }
    return bad != 0;
}

}  // namespace avsplat::detail
