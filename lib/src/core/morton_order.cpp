#include "avsplat/core/morton_order.h"

#include "common/radix_sort.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

namespace {

// Gaussians per chunk of a compressed PLY: buckets of more equal codes are sorted again.
constexpr std::size_t kChunk = 256;

// Morton order, as splat-transform's sortMortonStrided.

std::uint32_t part1by2(std::uint32_t v) {
    v &= 0x000003ffu;
    v = (v ^ (v << 16)) & 0xff0000ffu;
    v = (v ^ (v << 8)) & 0x0300f00fu;
    v = (v ^ (v << 4)) & 0x030c30c3u;
    v = (v ^ (v << 2)) & 0x09249249u;
    return v;
}

void morton_sort(std::size_t* idx, std::size_t n, const float* means) {
    if (n == 0) return;
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = std::numeric_limits<double>::infinity();
        hi[a] = -std::numeric_limits<double>::infinity();
    }
    for (std::size_t k = 0; k < n; ++k)
        for (int a = 0; a < 3; ++a) {
            const double v = means[3 * idx[k] + a];
            lo[a] = std::min(lo[a], v);
            hi[a] = std::max(hi[a], v);
        }
    double mul[3];
    bool all_zero = true;
    for (int a = 0; a < 3; ++a) {
        const double len = hi[a] - lo[a];
        if (!std::isfinite(len)) return;
        all_zero = all_zero && len == 0;
        mul[a] = len == 0 ? 0 : 1024 / len;
    }
    if (all_zero) return;
    // (code, position) in one integer; a stable radix sort over the 30 code bits (the order of
    // a stable sort by code: equal codes keep their order).
    if (n > 0xFFFFFFFFu) throw std::invalid_argument("morton_order: more than 2^32 - 1 Gaussians");
    std::vector<std::uint64_t> keyed(n), scratch(n);
    for (std::size_t k = 0; k < n; ++k) {
        std::uint32_t c[3];
        for (int a = 0; a < 3; ++a)
            c[a] = static_cast<std::uint32_t>(std::min(1023.0, (double(means[3 * idx[k] + a]) - lo[a]) * mul[a]));
        const std::uint32_t code = (part1by2(c[2]) << 2) + (part1by2(c[1]) << 1) + part1by2(c[0]);
        keyed[k] = (std::uint64_t(code) << 32) | k;
    }
    const std::uint64_t* sorted = radix_sort(keyed.data(), scratch.data(), n, 32, 62);
    {
        const std::vector<std::size_t> before(idx, idx + n);
        for (std::size_t k = 0; k < n; ++k) idx[k] = before[std::size_t(sorted[k] & 0xFFFFFFFFu)];
    }
    // Buckets of more than one chunk's worth of equal codes are ordered again over their own
    // bounds; each level splits a bucket (its extremes get different codes), so this ends.
    for (std::size_t start = 0; start < n;) {
        std::size_t end = start + 1;
        while (end < n && (sorted[end] >> 32) == (sorted[start] >> 32)) ++end;
        if (end - start > kChunk) morton_sort(idx + start, end - start, means);
        start = end;
    }
}

}  // namespace

std::vector<std::size_t> morton_order(const GaussianCloud& cloud) {
    std::vector<std::size_t> order(cloud.size());
    std::iota(order.begin(), order.end(), std::size_t(0));
    return morton_order(cloud, std::move(order));
}

std::vector<std::size_t> morton_order(const GaussianCloud& cloud, std::vector<std::size_t> rows) {
    if (cloud.means.size() != 3 * cloud.size())
        throw std::invalid_argument("GaussianCloud.means: " + std::to_string(cloud.means.size()) + " values for " +
                                    std::to_string(cloud.size()) + " Gaussians");
    for (std::size_t k = 0; k < rows.size(); ++k)
        if (rows[k] >= cloud.size())
            throw std::out_of_range("morton_order: rows[" + std::to_string(k) + "] = " + std::to_string(rows[k]) +
                                    " >= size " + std::to_string(cloud.size()));
    morton_sort(rows.data(), rows.size(), cloud.means.data());
    return rows;
}

}  // namespace avsplat
