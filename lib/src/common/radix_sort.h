// Stable LSD radix sort of records on a range of the bits of their 64-bit keys, parallel with
// OpenMP: the one radix sort of the CPU code (voxel keys in fusion/voxel_grid.cpp, depth keys with
// their tile rectangles in render/cpu/render_cpu.cpp). The result is the unique stable order, so
// it does not depend on the thread count or on how the passes are split.
#pragma once

#include "common/stop_check.h"
#include "common/parallel.h"

#include <omp.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat {

/// Index of the first of n items that thread t of `threads` handles in a static split.
inline std::size_t chunk_begin(std::size_t n, int t, int threads) {
    return n * static_cast<std::size_t>(t) / static_cast<std::size_t>(threads);
}

namespace radix_detail {

// Stable parallel LSD sort of a[0..n) on key bits [lo_bit, hi_bit); tmp has room for n. Returns
// the buffer that holds the result. Each pass: every thread counts the digits of its contiguous
// chunk, then (after a barrier) computes its own scatter offsets from all counts in (digit,
// thread) order and scatters its chunk in input order, so the result is the unique stable order
// whatever the thread count. One parallel region and two barriers per pass keep the
// synchronisation cheap; a pass whose digit is constant is skipped.
template <class Record, class KeyOf>
Record* parallel_lsd_sort(Record* a, Record* tmp, std::size_t n, int lo_bit, int hi_bit, const KeyOf& key) {
    const int bits = hi_bit - lo_bit;
    if (bits <= 0 || n < 2) return a;
    const int passes = (bits + 10) / 11;
    const int digit = (bits + passes - 1) / passes;
    const std::size_t max_buckets = std::size_t{1} << digit;
    const int max_threads = threads_for(n);
    std::vector<std::size_t> counts(max_buckets * static_cast<std::size_t>(max_threads));
    Record* result = a;
#pragma omp parallel num_threads(max_threads)
    {
        const int threads = omp_get_num_threads(), t = omp_get_thread_num();
        const std::size_t b = chunk_begin(n, t, threads), e = chunk_begin(n, t + 1, threads);
        std::vector<std::size_t> offset(max_buckets);
        Record* src = a;
        Record* dst = tmp;
        for (int pass = 0; pass < passes; ++pass) {
            const int shift = lo_bit + pass * digit;
            const int width = std::min(digit, hi_bit - shift);
            const std::size_t buckets = std::size_t{1} << width;
            const std::uint64_t mask = buckets - 1;
            std::size_t* mine = counts.data() + max_buckets * static_cast<std::size_t>(t);
            std::fill(mine, mine + buckets, std::size_t{0});
            for (std::size_t i = b; i < e; ++i) ++mine[(key(src[i]) >> shift) & mask];
#pragma omp barrier
            std::size_t sum = 0;
            bool constant = false;
            for (std::size_t d = 0; d < buckets; ++d) {
                std::size_t in_digit = 0;
                for (int u = 0; u < threads; ++u) {
                    const std::size_t c = counts[max_buckets * static_cast<std::size_t>(u) + d];
                    if (u == t) offset[d] = sum + in_digit;
                    in_digit += c;
                }
                sum += in_digit;
                constant = constant || in_digit == n;
            }
            if (!constant) {
                for (std::size_t i = b; i < e; ++i) dst[offset[(key(src[i]) >> shift) & mask]++] = src[i];
                std::swap(src, dst);
            }
            // Every thread has read the counts and written its part before the next pass.
#pragma omp barrier
        }
        if (t == 0) result = src;
    }
    return result;
}

// Stable LSD sort of a[0..n) on key bits [lo_bit, hi_bit) on the calling thread, 8-bit digits,
// with buf (room for n) as the other buffer; a pass whose digit is constant is skipped. Leaves
// the result in a.
template <class Record, class KeyOf>
void local_lsd_sort(Record* a, Record* buf, std::size_t n, int lo_bit, int hi_bit, const KeyOf& key) {
    Record* src = a;
    Record* dst = buf;
    std::size_t count[256];
    for (int shift = lo_bit; shift < hi_bit; shift += 8) {
        const int width = std::min(8, hi_bit - shift);
        const std::uint64_t mask = (std::uint64_t{1} << width) - 1;
        std::fill(count, count + (std::size_t{1} << width), std::size_t{0});
        for (std::size_t i = 0; i < n; ++i) ++count[(key(src[i]) >> shift) & mask];
        std::size_t sum = 0;
        bool constant = false;
        for (std::size_t d = 0; d < (std::size_t{1} << width); ++d) {
            const std::size_t c = count[d];
            constant = constant || c == n;
            count[d] = sum;
            sum += c;
        }
        if (constant) continue;
        for (std::size_t i = 0; i < n; ++i) dst[count[(key(src[i]) >> shift) & mask]++] = src[i];
        std::swap(src, dst);
    }
    if (src != a) std::copy_n(src, n, a);
}

}  // namespace radix_detail

/// Stably sorts a[0..n) by bits [lo_bit, hi_bit) of key(record) (a std::uint64_t); the key bits
/// below lo_bit are ignored, those from hi_bit on must be zero. tmp has room for n records.
/// Returns the buffer, a or tmp, that holds the result; the other is left unspecified.
///
/// Large inputs take one parallel pass over memory on the top digit (up to 11 bits), which
/// leaves buckets of a few thousand records; each bucket is then sorted on the remaining bits on
/// one thread, in its cache. Buckets too large for that go through the parallel sort.
///
/// With a `poll`, the bucket sorts stop when it says stop and the result is unspecified: the
/// caller reports the stop after it (InterruptPoll::throw_if_stopped()).
template <class Record, class KeyOf>
Record* radix_sort(Record* a, Record* tmp, std::size_t n, int lo_bit, int hi_bit, const KeyOf& key,
                   StopCheck* poll = nullptr) {
    using radix_detail::local_lsd_sort;
    using radix_detail::parallel_lsd_sort;
    constexpr std::size_t kLocalBytes = std::size_t(1) << 19;  // twice this fits the L2 cache
    const std::size_t local = std::max<std::size_t>(kLocalBytes / sizeof(Record), 1024);
    const int bits = hi_bit - lo_bit;
    if (bits <= 11 || n <= local) return parallel_lsd_sort(a, tmp, n, lo_bit, hi_bit, key);
    const int split = hi_bit - 11;
    Record* buckets = parallel_lsd_sort(a, tmp, n, split, hi_bit, key);
    Record* other = buckets == a ? tmp : a;
    // Bucket boundaries, by binary search on the top digit.
    const std::size_t digits = std::size_t{1} << (hi_bit - split);
    std::vector<std::size_t> starts(digits + 1);
    for (std::size_t d = 0; d <= digits; ++d)
        starts[d] = std::size_t(std::partition_point(buckets, buckets + n, [&](const Record& x) {
                                    return (key(x) >> split) < d;
                                }) - buckets);
    const std::int64_t count = static_cast<std::int64_t>(digits);
    std::vector<std::int64_t> large;
#pragma omp parallel num_threads(threads_for(n))
    {
        std::vector<Record> buf;
#pragma omp for schedule(dynamic, 4)
        for (std::int64_t k = 0; k < count; ++k) {
            if (poll && poll->should_stop()) continue;
            const std::size_t b = starts[std::size_t(k)], e = starts[std::size_t(k) + 1];
            if (e - b > local) {
#pragma omp critical(avsplat_radix_large)
                large.push_back(k);
                continue;
            }
            if (buf.size() < e - b) buf.resize(e - b);
            local_lsd_sort(buckets + b, buf.data(), e - b, lo_bit, split, key);
        }
    }
    std::sort(large.begin(), large.end());
    for (const std::int64_t k : large) {
        if (poll && poll->should_stop()) break;
        const std::size_t b = starts[std::size_t(k)], e = starts[std::size_t(k) + 1];
        const Record* r = parallel_lsd_sort(buckets + b, other + b, e - b, lo_bit, split, key);
        if (r != buckets + b) std::copy_n(r, e - b, buckets + b);
    }
    return buckets;
}

/// radix_sort of plain keys (the record is its key).
inline std::uint64_t* radix_sort(std::uint64_t* a, std::uint64_t* tmp, std::size_t n, int lo_bit, int hi_bit) {
    return radix_sort(a, tmp, n, lo_bit, hi_bit, [](std::uint64_t k) { return k; });
}

}  // namespace avsplat
