// When the CPU loops of the library go parallel.
#pragma once

#include <omp.h>

#include <cstddef>

namespace avsplat {

/// Below this many items a loop runs on the calling thread: starting threads would cost more
/// than it saves, and small calls stay fast when the cores are busy with other work. Results
/// never depend on it (every parallel loop gives the same result on any number of threads).
constexpr std::size_t kParallelMin = std::size_t(1) << 14;

/// Threads for a loop over n items: OpenMP's maximum from kParallelMin items on, else 1.
inline int threads_for(std::size_t n) { return n >= kParallelMin ? omp_get_max_threads() : 1; }

}  // namespace avsplat
