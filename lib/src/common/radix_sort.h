// Stable LSD radix sort of 64-bit keys on a range of their bits, parallel with OpenMP. The
// result is the unique stable order, so it does not depend on the thread count.
#pragma once

#include <cstddef>
#include <cstdint>

namespace avsplat {

/// Index of the first of n items that thread t of `threads` handles in a static split.
inline std::size_t chunk_begin(std::size_t n, int t, int threads) {
    return n * static_cast<std::size_t>(t) / static_cast<std::size_t>(threads);
}

/// Stably sorts a[0..n) on bits [lo_bit, hi_bit) of each key; the bits below lo_bit are carried
/// along and ignored, the bits from hi_bit on must be zero. tmp has room for n keys. Returns the buffer, a or tmp, that holds the result;
/// the other one is left in an unspecified state.
std::uint64_t* radix_sort(std::uint64_t* a, std::uint64_t* tmp, std::size_t n, int lo_bit, int hi_bit);

}  // namespace avsplat
