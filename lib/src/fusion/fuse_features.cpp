// fuse_voxels: one fused feature vector (and position) per occupied voxel.
#include "avsplat/fusion/fusion.h"

#include "common/finite_scan.h"
#include "common/huge_pages.h"
#include "core/interrupt_poll.h"
#include "core/progress_report.h"
#include "common/parallel.h"
#include "core/invalid_samples.h"
#include "fusion/block_weigher.h"
#include "fusion/checks.h"
#include "fusion/weighted_rows.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

namespace {

using namespace fusion_detail;

// Fuses every voxel of `grid` (over the n input samples). Returns false when some voxel met a
// non-finite feature (the output is then incomplete and the caller finds and handles the bad
// sample).
template <class T>
bool fuse_features_pass(const SparseVoxelGrid& grid, const float* positions, std::size_t n_input,
                        const float* confidence, const float* features, std::size_t channels,
                        const FusionParams& p, FeatureFusionResult& out) {
    const std::size_t m = grid.num_voxels();
    const std::size_t total = grid.sample_indices().size();
    const std::int64_t* offsets = grid.voxel_offsets().data();
    const bool parallel = total >= kParallelMin;
    out.positions.resize(3 * m);
    allocate_diagnostics(out.diagnostics, m);
    // Pass 1 writes each voxel's samples in canonical order with their weights, in CSR layout;
    // pass 2 reads them to average the feature rows.
    std::unique_ptr<std::int32_t[]> canonical_ids(channels ? new std::int32_t[total] : nullptr);
    std::unique_ptr<T[]> canonical_weights(channels ? new T[total] : nullptr);
    if (channels) {
        advise_huge_pages(canonical_ids.get(), total * sizeof(std::int32_t));
        advise_huge_pages(canonical_weights.get(), total * sizeof(T));
    }
    std::int32_t* cids = canonical_ids.get();
    T* cw = canonical_weights.get();
    TieFields ties;
    if (channels) ties.push_back({features, channels});

    // Pass 1: weights, diagnostics and fused positions. Meanwhile one thread allocates and
    // zero-fills the feature output, a serial memset that would otherwise hold up every thread.
    const std::int64_t blocks = std::int64_t((m + kBlockVoxels - 1) / kBlockVoxels);
    InterruptPoll poll;
    // One block of voxels: weights, diagnostics and fused positions.
    auto weigh_block = [&](BlockWeigher<T>& weigher, std::int64_t block) {
        const std::size_t v0 = std::size_t(block) * kBlockVoxels, v1 = std::min(m, v0 + kBlockVoxels);
        weigher.run(v0, v1);
        for (std::size_t v = v0; v < v1; ++v) {
            const std::size_t n = weigher.size(v);
            store_diagnostics(out.diagnostics, v, n, weigher.stats(v));
            float* out_p = out.positions.data() + 3 * v;
            const float* pos = weigher.positions(v);
            const T* w = weigher.weights(v);
            if (n == 1) {
                std::copy_n(pos, 3, out_p);
                continue;
            }
            double pacc[3] = {0.0, 0.0, 0.0}, wsum = 0.0;
            for (std::size_t k = 0; k < n; ++k) {
                const double wk = double(w[k]);
                for (int a = 0; a < 3; ++a) pacc[a] += wk * double(pos[3 * k + a]);
                wsum += wk;
            }
            const double inv = 1.0 / wsum;
            for (int a = 0; a < 3; ++a) out_p[a] = float(pacc[a] * inv);
        }
    };
#pragma omp parallel if (parallel)
    {
#pragma omp single nowait
        poll.guard([&] {
            reserve_huge(out.features, m * channels);
            out.features.resize(m * channels);
        });
        std::optional<BlockWeigher<T>> weigher;
        poll.guard([&] { weigher.emplace(grid, ties, p, positions, confidence, cids, cw); });
#pragma omp for schedule(dynamic, 2)
        for (std::int64_t block = 0; block < blocks; ++block) {
            if (poll.stop() || !weigher) continue;
            poll.guard([&] { weigh_block(*weigher, block); });
        }
    }
    poll.throw_if_stopped();
    if (!channels) return true;

    // Pass 2: the weighted feature rows, scattered over the input. The loop walks the samples in
    // CSR order and keeps the row of the sample kRowsAhead further on in flight, so that rows
    // arrive at a steady rate whatever the voxels' sizes.
    // A voxel's weights decrease along its canonical order, so the samples that trimming left
    // out (weight 0; also softmax weights that underflowed) are its last ones. When every input
    // row is finite, their rows change no sum (the sums start at +0, and 0 * x, a zero, added to
    // them leaves them as they are), so the loop neither fetches nor reads them: with the paper's
    // trim mass of 0.8 about 70 % of the rows of the benchmark's 2M samples. Whether every row is
    // finite costs one sequential read of the features, cheaper than the scattered reads it
    // saves (docs/benchmarks/fusion.md); otherwise every row is read, so that a NaN/Inf shows in the sums
    // and the caller finds and handles it as before.
    constexpr std::int64_t kRowsAhead = 24;
    const std::int64_t grouped = std::int64_t(total);
    // Only a pass with zero weights has rows to skip (trimming, sparsemax, a softmax weight that
    // underflowed: pass 1 counted the others in `kept`); `mean` and plain `softmax` pay no scan.
    std::size_t nonzero = 0;
    for (std::size_t v = 0; v < m; ++v) nonzero += std::size_t(out.diagnostics.kept[v]);
    const bool skip_zero_weights = nonzero < total && !detail::any_non_finite_parallel(features, n_input * channels);
    const auto needed = [&](std::int64_t s) { return !skip_zero_weights || cw[s] != T(0); };
    bool finite = true;
#pragma omp parallel reduction(&& : finite) if (parallel)
    {
        std::vector<double> wd;
        std::int64_t fetched = 0;  // rows of the samples before this one are in flight
#pragma omp for schedule(dynamic, 256)
        for (std::int64_t vv = 0; vv < std::int64_t(m); ++vv) {
            if (poll.stop(vv)) continue;
            const std::size_t v = std::size_t(vv);
            const std::size_t b = std::size_t(offsets[v]);
            const std::size_t n = std::size_t(offsets[v + 1]) - b;
            // A new stretch of voxels starts at this one's samples.
            if (fetched < std::int64_t(b) || fetched > std::int64_t(b + n) + kRowsAhead) fetched = std::int64_t(b);
            for (const std::int64_t until = std::min(grouped, std::int64_t(b + n) + kRowsAhead); fetched < until; ++fetched)
                if (needed(fetched)) prefetch_row(features + channels * std::size_t(cids[fetched]), channels);
            float* out_f = out.features.data() + channels * v;
            if (n == 1) {
                std::copy_n(features + channels * std::size_t(cids[b]), channels, out_f);
                for (std::size_t c = 0; c < channels; ++c) finite = finite && std::isfinite(out_f[c]);
                continue;
            }
            std::size_t used = n;  // the voxel's samples up to its last one that is needed
            while (used > 1 && !needed(std::int64_t(b + used - 1))) --used;
            if (wd.size() < used) {
                poll.guard([&] { wd.resize(used); });  // std::bad_alloc stops the loop
                if (wd.size() < used) continue;
            }
            double wsum = 0.0;  // the same sum as pass 1's (its zeros add nothing), so the same 1 / wsum
            for (std::size_t k = 0; k < used; ++k) {
                wd[k] = double(cw[b + k]);
                wsum += wd[k];
            }
            finite = weighted_rows(features, channels, cids + b, wd.data(), used, 1.0 / wsum, out_f) && finite;
        }
    }
    poll.throw_if_stopped();
    return finite;
}

template <class T>
FeatureFusionResult fuse_features(const float* positions, std::size_t n, const float* features,
                                  std::size_t channels, double voxel_size, const float* confidence,
                                  const FusionParams& p) {
    ProgressReport report(n);  // samples, reported at the start and the end only
    std::vector<std::uint8_t> keep;
    check_confidence(confidence, n, p, "confidence", keep);
    FeatureFusionResult out;
    out.channels = int(channels);
    for (int attempt = 0; attempt < 2; ++attempt) {
        SparseVoxelGrid grid(positions, n, voxel_size, p.on_invalid, keep.empty() ? nullptr : keep.data(),
                             "positions");
        if (fuse_features_pass<T>(grid, positions, n, confidence, features, channels, p, out)) {
            out.dropped = grid.dropped();
            out.voxel_coords = std::move(grid).voxel_coords();
            out.sample_voxel = std::move(grid).sample_voxel();
            report.finish();
            return out;
        }
        // A NaN/Inf feature reached a sum: find the first one in input order.
        const auto bad_row = [&](std::size_t i) {
            if (!keep.empty() && !keep[i]) return false;
            const float* f = features + channels * i;
            for (std::size_t c = 0; c < channels; ++c)
                if (!std::isfinite(f[c])) return true;
            return false;
        };
        const bool any_bad = apply_invalid_policy(n, bad_row, p.on_invalid, keep, [&](std::size_t first) {
            const float* f = features + channels * first;
            std::size_t c = 0;
            while (std::isfinite(f[c])) ++c;
            throw std::invalid_argument(feature_error(first, c, f[c]));
        });
        if (!any_bad) break;  // cannot happen: the sums are finite for finite inputs
    }
    throw std::logic_error("fuse_voxels: non-finite fused feature from finite inputs");
}

}  // namespace

FeatureFusionResult fuse_voxels(const float* positions, std::size_t n, const float* features,
                                int channels, double voxel_size, const float* confidence,
                                const FusionParams& params) {
    validate(params);
    if (channels < 0) throw std::invalid_argument("features: channels = " + std::to_string(channels) + " < 0");
    if (n > 0 && channels > 0 && !features) throw std::invalid_argument("features: null array");
    if (params.precision == Precision::Float64)
        return fuse_features<double>(positions, n, features, std::size_t(channels), voxel_size, confidence, params);
    return fuse_features<float>(positions, n, features, std::size_t(channels), voxel_size, confidence, params);
}

}  // namespace avsplat
