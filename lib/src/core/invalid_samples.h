// The "first bad index, then raise or drop" step of every input check: find the first invalid
// sample in input order (so the error names it whatever the thread count), then either throw
// or clear its keep flag and every later invalid one's.
#pragma once

#include "avsplat/core/invalid_policy.h"
#include "common/parallel.h"

#include <omp.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace avsplat {

/// No index: what first_bad_index returns when every sample is valid.
constexpr std::size_t kNoIndex = std::numeric_limits<std::size_t>::max();

/// First index in [0, n) for which bad(i) holds, or kNoIndex. Parallel from kParallelMin
/// samples on; the result is the smallest such index for any thread count.
template <class Bad>
std::size_t first_bad_index(std::size_t n, Bad bad) {
    std::size_t first = kNoIndex;
#pragma omp parallel if (n >= kParallelMin)
    {
        const std::size_t threads = std::size_t(omp_get_num_threads()), t = std::size_t(omp_get_thread_num());
        const std::size_t b = n * t / threads, e = n * (t + 1) / threads;
        std::size_t mine = kNoIndex;
        for (std::size_t i = b; i < e; ++i) {
            if (bad(i)) {
                mine = i;
                break;
            }
        }
#pragma omp critical(avsplat_first_bad)
        first = std::min(first, mine);
    }
    return first;
}

/// Applies `policy` to the samples i < n for which bad(i) holds. None bad: returns false and
/// leaves keep alone. Raise: calls raise(first) with the first bad index; raise must throw.
/// Drop: sizes keep to n ones if it is empty, clears keep[i] for every bad i and returns true.
/// keep: n flags (1 keeps the sample) or empty.
template <class Bad, class Raise>
bool apply_invalid_policy(std::size_t n, Bad bad, InvalidPolicy policy, std::vector<std::uint8_t>& keep,
                          Raise raise) {
    const std::size_t first = first_bad_index(n, bad);
    if (first == kNoIndex) return false;
    if (policy == InvalidPolicy::Raise) raise(first);
    if (keep.empty()) keep.assign(n, 1);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
    for (std::int64_t i = std::int64_t(first); i < std::int64_t(n); ++i)
        if (bad(std::size_t(i))) keep[std::size_t(i)] = 0;
    return true;
}

}  // namespace avsplat
