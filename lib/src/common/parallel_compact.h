// Stable parallel compaction: the records of an array that a predicate keeps, in their order.
#pragma once

#include "common/parallel.h"

#include <omp.h>

#include <cstddef>
#include <vector>

namespace avsplat {

/// Copies the records of in[0, n) for which keep(record) holds to out (room for n), in their
/// order, and returns how many. Each thread counts and then copies one contiguous part, placed
/// by the counts of the parts before it, so the result is that of the serial loop on any
/// number of threads.
template <class T, class Keep>
std::size_t parallel_compact(const T* in, std::size_t n, T* out, Keep keep) {
    const int most = threads_for(n);
    std::vector<std::size_t> start(std::size_t(most) + 1, 0);
    std::size_t used = 0;  // threads in the team (at most `most`)
#pragma omp parallel num_threads(most)
    {
        const std::size_t parts = std::size_t(omp_get_num_threads()), p = std::size_t(omp_get_thread_num());
        const std::size_t lo = n * p / parts, hi = n * (p + 1) / parts;
        std::size_t count = 0;
        for (std::size_t i = lo; i < hi; ++i) count += keep(in[i]) ? 1 : 0;
        start[p + 1] = count;
#pragma omp barrier
#pragma omp single
        {
            used = parts;
            for (std::size_t q = 0; q < parts; ++q) start[q + 1] += start[q];
        }
        std::size_t o = start[p];
        for (std::size_t i = lo; i < hi; ++i)
            if (keep(in[i])) out[o++] = in[i];
    }
    return start[used];
}

}  // namespace avsplat
