// Private to FusionStream: the input checks of one chunk, with the operator's own code, in the
// operator's order (features: confidence, non-finite positions, positions whose key overflows,
// non-finite features; Gaussians: validity, confidence, key overflow). Raise: the first chunk that
// holds an invalid sample raises at once, as the operator would on that chunk, naming the global
// index. Drop: the samples the operator would drop are dropped here and counted.
#pragma once

#include "avsplat/core/invalid_policy.h"
#include "core/invalid_samples.h"
#include "fusion/checks.h"
#include "fusion/stream_keys.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat::detail {

struct ChunkChecks {
    InvalidPolicy policy;
    double voxel_size;
    std::size_t first;      // the chunk's first sample, as a global index
    std::size_t& dropped;   // the stream's count of samples dropped by these checks

    std::string globalise(const std::string& what) const {
        return globalise_message(what, [&](std::size_t local) { return first + local; });
    }

    // Runs check(keep), an operator's check of the chunk, naming global indices.
    template <class Check>
    void run(std::vector<std::uint8_t>& keep, const Check& check) const {
        try {
            check(keep);
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument(globalise(e.what()));
        }
    }

    // The rows that pass the checks so far (keep: empty, or n flags with 0 for a sample already
    // dropped) and whose position has a key; checks the positions as the voxel grid does.
    std::vector<std::uint32_t> rows_with_keys(const float* pos, std::size_t n, const std::vector<std::uint8_t>& keep,
                                              const char* field) const {
        const bool drop = policy == InvalidPolicy::Drop;
        std::vector<std::uint32_t> rows;
        rows.reserve(n);
        std::size_t first_nonfinite = kNoIndex, first_overflow = kNoIndex;
        for (std::size_t i = 0; i < n; ++i) {
            if (!keep.empty() && !keep[i]) {
                ++dropped;
                continue;
            }
            bool finite = true, fits = true;
            for (int a = 0; a < 3 && finite; ++a) {
                const double x = double(pos[3 * i + a]) / voxel_size;
                finite = std::isfinite(pos[3 * i + a]);
                fits = fits && x > kKeyLow && x < kKeyHigh;
            }
            if (finite && fits) {
                rows.push_back(std::uint32_t(i));
            } else if (!finite) {
                if (drop) ++dropped;
                else first_nonfinite = std::min(first_nonfinite, i);
            } else {
                first_overflow = std::min(first_overflow, i);
            }
        }
        // As the voxel grid: non-finite coordinates first (Raise), then keys that overflow.
        for (std::size_t i : {first_nonfinite, first_overflow})
            if (i != kNoIndex) throw std::invalid_argument(globalise(position_error(pos, i, voxel_size, field)));
        return rows;
    }

    // Raise: the operator's check of the n x c features (under Raise it drops nothing, so it
    // sees every sample). Drop: nothing here; the operator drops them when it fuses.
    void features(const float* f, std::size_t n, std::size_t c) const {
        if (policy != InvalidPolicy::Raise || c == 0) return;
        const std::size_t bad = first_bad_index(n, [&](std::size_t i) {
            for (std::size_t j = 0; j < c; ++j)
                if (!std::isfinite(f[c * i + j])) return true;
            return false;
        });
        if (bad == kNoIndex) return;
        std::size_t j = 0;
        while (std::isfinite(f[c * bad + j])) ++j;
        throw std::invalid_argument(fusion_detail::feature_error(first + bad, j, f[c * bad + j]));
    }
};

}  // namespace avsplat::detail
