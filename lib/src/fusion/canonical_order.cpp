#include "fusion/canonical_order.h"

#include "common/order_key.h"
#include "common/rank16.h"

#include <algorithm>
#include <cstring>

namespace avsplat::fusion_detail {

namespace {

inline std::uint32_t float_bits(float f) {
    std::uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
}

inline int compare_bits(const float* a, const float* b, std::size_t n) {
    for (std::size_t k = 0; k < n; ++k) {
        const std::uint32_t x = float_bits(a[k]), y = float_bits(b[k]);
        if (x != y) return x < y ? -1 : 1;
    }
    return 0;
}

// Bit-pattern order of local sample slots (the order of the file comment).
struct CanonicalLess {
    const VoxelSamples* s;
    const TieFields* ties;
    bool operator()(std::int32_t a, std::int32_t b) const {
        int c = compare_bits(s->positions + 3 * a, s->positions + 3 * b, 3);
        if (c) return c < 0;
        if (s->confidence) {
            c = compare_bits(s->confidence + a, s->confidence + b, 1);
            if (c) return c < 0;
        }
        const std::size_t ia = std::size_t(s->ids[a]), ib = std::size_t(s->ids[b]);
        for (const RowField& f : *ties) {
            c = compare_bits(f.data + f.width * ia, f.data + f.width * ib, f.width);
            if (c) return c < 0;
        }
        return ia < ib;
    }
};

}  // namespace

void canonical_order(const VoxelSamples& s, const TieFields& ties, CanonicalScratch& scratch) {
    // Order by decreasing confidence (without confidence: by the bits of x), then resolve
    // runs of equal keys with the full canonical comparison. Ordered by confidence, the
    // weights decrease along the voxel, so trimming needs no sort. The few samples of a
    // typical voxel are ranked by counting (no unpredictable branch; up to 16 in SSE2
    // registers), larger voxels by sorting (key, slot) integers.
    const std::size_t n = s.n;
    scratch.sort_keys.resize(std::max<std::size_t>(n, 16));
    scratch.slots.resize(n);
    if (s.confidence)
        for (std::size_t k = 0; k < n; ++k) scratch.sort_keys[k] = float_descending_key(s.confidence[k]);
    else
        for (std::size_t k = 0; k < n; ++k) scratch.sort_keys[k] = float_bits(s.positions[3 * k]);
    if (n <= 16) {
        std::fill(scratch.sort_keys.begin() + std::ptrdiff_t(n), scratch.sort_keys.begin() + 16, ~std::uint32_t(0));
        int rank[16];
        rank_ascending16(scratch.sort_keys.data(), int(n), rank);
        for (int i = 0; i < int(n); ++i) scratch.slots[std::size_t(rank[i])] = i;
    } else {
        // (key, slot) packed in one integer: a plain integer sort, ties by slot.
        scratch.keyed_slots.resize(n);
        for (std::size_t k = 0; k < n; ++k) scratch.keyed_slots[k] = (std::uint64_t(scratch.sort_keys[k]) << 32) | std::uint64_t(k);
        std::sort(scratch.keyed_slots.begin(), scratch.keyed_slots.end());
        for (std::size_t k = 0; k < n; ++k) scratch.slots[k] = std::int32_t(scratch.keyed_slots[k] & 0xFFFFFFFFu);
    }
    for (std::size_t i = 0; i < n;) {
        std::size_t j = i + 1;
        const std::uint32_t xi = scratch.sort_keys[std::size_t(scratch.slots[i])];
        while (j < n && scratch.sort_keys[std::size_t(scratch.slots[j])] == xi) ++j;
        if (j - i > 1) std::sort(scratch.slots.begin() + std::ptrdiff_t(i), scratch.slots.begin() + std::ptrdiff_t(j), CanonicalLess{&s, &ties});
        i = j;
    }
}

}  // namespace avsplat::fusion_detail
