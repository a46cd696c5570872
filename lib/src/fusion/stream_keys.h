// Private to FusionStream: the voxel keys that route samples to blocks, the blocks' bounds, and
// the operator's error messages rewritten to the stream's global sample indices.
#pragma once

#include "avsplat/fusion/voxel_grid.h"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat::detail {

// round(x) fits int32 exactly when x lies strictly inside these bounds (as SparseVoxelGrid).
constexpr double kKeyLow = -2147483648.5;
constexpr double kKeyHigh = 2147483647.5;

// A voxel key (kx, ky, kz). Blocks are ranges of keys in lexicographic order, the order in
// which the operator returns its voxels, so one dense slab of kx (or column of (kx, ky)) is cut
// further and only a single voxel can never be split.
using Key = std::array<std::int32_t, 3>;
constexpr Key kMinKey{std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::min(),
                      std::numeric_limits<std::int32_t>::min()};

// The block of `key`: bounds[0] is kMinKey and bounds increase strictly.
inline std::size_t block_of(const std::vector<Key>& bounds, const Key& key) {
    return std::size_t(std::upper_bound(bounds.begin(), bounds.end(), key) - bounds.begin()) - 1;
}

// Lower bounds of up to `blocks` key ranges holding about equal numbers of the given keys.
inline std::vector<Key> quantile_bounds(std::vector<Key> keys, std::size_t blocks) {
    std::vector<Key> bounds{kMinKey};
    if (keys.empty() || blocks < 2) return bounds;
    std::sort(keys.begin(), keys.end());
    for (std::size_t j = 1; j < blocks; ++j) {
        const Key& b = keys[j * keys.size() / blocks];
        // The first range starts at kMinKey, so a bound at the smallest key would only add an
        // empty range (and a split that never shrinks the block).
        if (bounds.back() < b && keys.front() < b) bounds.push_back(b);
    }
    return bounds;
}

// Replaces the first "[<local index>" of an operator's error message by global(local index).
template <class Global>
std::string globalise_message(const std::string& what, const Global& global) {
    const std::size_t open = what.find('[');
    if (open == std::string::npos) return what;
    std::size_t end = open + 1;
    while (end < what.size() && what[end] >= '0' && what[end] <= '9') ++end;
    if (end == open + 1) return what;
    const std::size_t local = std::stoull(what.substr(open + 1, end - open - 1));
    return what.substr(0, open + 1) + std::to_string(global(local)) + what.substr(end);
}

inline std::string globalise_message(const std::string& what, const std::vector<std::uint64_t>& index) {
    return globalise_message(what, [&](std::size_t local) { return local < index.size() ? index[local] : local; });
}

// The message the operator gives for sample `i` of `positions` (non-finite or a key outside
// int32), from the voxel grid itself, so that the stream's words are the operator's; "" when
// the sample is fine.
inline std::string position_error(const float* positions, std::size_t i, double voxel_size, const char* field) {
    try {
        SparseVoxelGrid one(positions + 3 * i, 1, voxel_size, InvalidPolicy::Raise, nullptr, field);
    } catch (const std::invalid_argument& e) {
        return globalise_message(e.what(), [&](std::size_t) { return i; });
    }
    return {};
}

}  // namespace avsplat::detail
