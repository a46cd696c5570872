// BlockWeigher: canonical order, weights and diagnostics of blocks of consecutive voxels, the
// per-voxel work shared by fuse_voxels and fuse_gaussians.
#pragma once

#include "avsplat/fusion/fusion.h"
#include "fusion/canonical_order.h"
#include "fusion/voxel_weights.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <vector>

namespace avsplat::fusion_detail {

namespace fw = fusion_weights;

// Voxels weighed together by BlockWeigher: enough to overlap their short computations, few
// enough that a block's scratch memory stays in the L1 and L2 caches.
constexpr std::size_t kBlockVoxels = 32;

// Starts fetching the positions (and confidences) of samples ids[0..n): the per-voxel loops
// read them through the grid's sample indices, scattered over the input, so they ask for a
// voxel's samples a few voxels ahead.
inline void prefetch_samples(const std::int32_t* ids, std::size_t n, const float* positions, const float* confidence) {
    for (std::size_t k = 0; k < n; ++k) {
        const std::size_t i = std::size_t(ids[k]);
        __builtin_prefetch(positions + 3 * i, 0, 2);
        __builtin_prefetch(positions + 3 * i + 2, 0, 2);  // a position may straddle two cache lines
        if (confidence) __builtin_prefetch(confidence + i, 0, 2);
    }
}

struct VoxelStats {
    double variance = 0.0;
    float temperature = 0.f;
    float reliability = 0.f;
    float entropy = 0.f;
    std::int32_t kept = 0;
};

// Per-thread worker of both fusion entry points: canonical order, weights and diagnostics of a block of consecutive voxels,
// with scratch memory reused across blocks. T is the scalar of the weight maths.
//
// Each step (canonical order, variance, reliability, temperature, exponentials, normalisation)
// runs over the whole block before the next one starts. A voxel holds about ten samples, so
// its sums are short dependency chains; taken voxel after voxel within a step, the chains of
// neighbouring voxels overlap in the CPU, and the exponentials of the block run four at a time
// in one stream. Each voxel's arithmetic is the same as if it were weighed alone, so results
// do not depend on how voxels are grouped into blocks.
template <class T>
class BlockWeigher {
public:
    // positions (n x 3) and confidence (n, or null) are the whole input, read through the
    // grid's sample indices. When canonical_ids and canonical_weights are given (one slot per
    // grouped sample, the grid's CSR layout), each voxel's canonical ids and weights are written
    // there, in its slots, rather than into scratch memory.
    BlockWeigher(const SparseVoxelGrid& grid, const TieFields& ties, const FusionParams& p, const float* positions,
                 const float* confidence, std::int32_t* canonical_ids = nullptr, T* canonical_weights = nullptr)
        : samples_(grid.sample_indices().data()),
          offsets_(grid.voxel_offsets().data()),
          voxels_(grid.num_voxels()),
          ties_(ties),
          params_(p),
          voxel_size_(grid.voxel_size()),
          in_positions_(positions),
          in_confidence_(confidence),
          csr_ids_(canonical_ids),
          csr_weights_(canonical_weights) {
        // The occupancy part of the temperature and log n depend on n only: tabulated for typical
        // voxels (the same function of the same argument, so the same bits as computing them).
        for (long long n = 1; n < kTable; ++n) {
            log_n_[n] = float(std::log(double(n)));
            if (p.policy == FusionPolicy::Occupancy)
                factor_[n] = fw::temperature_factor<T>(n, T(p.tau0), T(p.alpha), T(p.n_ref), T(p.eps));
        }
    }

    // Weighs the voxels [v0, v1) of the grid. Afterwards, for v in [v0, v1), ids(v)[k],
    // positions(v)[3k..3k+2] and weights(v)[k] describe the k-th sample of voxel v in canonical
    // order, k < size(v), and stats(v) its diagnostics.
    void run(std::size_t v0, std::size_t v1) {
        v0_ = v0;
        const std::size_t count = v1 - v0;
        start_.resize(count + 1);
        for (std::size_t v = 0; v <= count; ++v) start_[v] = std::size_t(offsets_[v0 + v] - offsets_[v0]);
        const std::size_t total = start_[count];
        const bool has_conf = in_confidence_ != nullptr;
        if (csr_ids_ && csr_weights_) {
            ids_out_ = csr_ids_ + offsets_[v0];
            weights_out_ = csr_weights_ + offsets_[v0];
        } else {
            ids_scratch_.resize(total);
            weights_scratch_.resize(total);
            ids_out_ = ids_scratch_.data();
            weights_out_ = weights_scratch_.data();
        }
        pos_.resize(3 * total);
        if (has_conf) conf_.resize(total);
        stats_.resize(count);
        tau_.resize(count);

        // Canonical order; the samples of a voxel a few ahead are fetched meanwhile.
        constexpr std::size_t kAhead = 8;
        for (std::size_t v = 0; v < count; ++v) {
            const std::size_t g = v0 + v + kAhead;
            if (g < voxels_) prefetch_samples(samples_ + offsets_[g], std::size_t(offsets_[g + 1] - offsets_[g]),
                                              in_positions_, in_confidence_);
            canonicalise(start_[v], samples_ + offsets_[v0 + v], size_at(v));
        }
        for (std::size_t v = 0; v < count; ++v) stats_[v].variance = size_at(v) > 1 ? variance(v) : 0.0;

        // Reliability from the mean confidence probability and the geometric consistency.
        if (has_conf) {
            probability_.resize(total);
            bool mapped = false;
            if constexpr (std::is_same_v<T, float>) {
                if (params_.confidence_mapping == ConfidenceMapping::Logit) {
                    fw::sigmoid<float>(conf_.data(), (long long)total, probability_.data());
                    mapped = true;
                }
            }
            if (!mapped)
                for (std::size_t k = 0; k < total; ++k) probability_[k] = fw::confidence_probability<T>(conf_[k], params_.confidence_mapping);
        }
        for (std::size_t v = 0; v < count; ++v) {
            const std::size_t n = size_at(v);
            double mean_q = 0.5;
            if (has_conf) {
                double sum_q = 0.0;
                for (std::size_t k = start_[v]; k < start_[v + 1]; ++k) sum_q += double(probability_[k]);
                mean_q = sum_q / double(n);
            }
            const T g = fw::geometric_consistency<T>(T(stats_[v].variance), T(voxel_size_), T(params_.eps));
            const T r = fw::reliability<T>(T(mean_q), g, T(params_.b_conf), T(params_.b_geo), T(params_.eps));
            VoxelStats& st = stats_[v];
            st.reliability = float(r);
            switch (params_.policy) {
                case FusionPolicy::Mean:
                    tau_[v] = std::numeric_limits<T>::infinity();
                    break;
                case FusionPolicy::Softmax:
                    tau_[v] = T(1);
                    break;
                case FusionPolicy::Occupancy: {
                    const T factor = (long long)n < kTable ? factor_[n]
                                                           : fw::temperature_factor<T>((long long)n, T(params_.tau0), T(params_.alpha),
                                                                                       T(params_.n_ref), T(params_.eps));
                    tau_[v] = fw::temperature_from_factor<T>(factor, r, T(params_.tau_min), T(params_.tau_max), T(params_.k_rel));
                    break;
                }
            }
            st.temperature = float(tau_[v]);
        }

        // Without confidence (or with one sample) all logits are equal: every policy gives the
        // plain average, and trimming keeps ties. Other voxels: softmax (AnySplat: of the raw
        // confidence, whatever the mapping) or the occupancy policy's softmax or sparsemax.
        const auto uniform = [&](std::size_t v) {
            return !has_conf || size_at(v) == 1 || params_.policy == FusionPolicy::Mean;
        };
        if (has_conf && params_.policy != FusionPolicy::Mean) {
            logits_.resize(total);
            if (params_.policy == FusionPolicy::Softmax || params_.confidence_mapping == ConfidenceMapping::Logit)
                for (std::size_t k = 0; k < total; ++k) logits_[k] = T(conf_[k]);
            else
                for (std::size_t k = 0; k < total; ++k) logits_[k] = fw::confidence_logit<T>(conf_[k], params_.confidence_mapping);
            const double trim = params_.policy == FusionPolicy::Occupancy ? params_.trim_mass : 0.0;
            if (params_.policy == FusionPolicy::Occupancy && params_.weights == WeightFunction::Sparsemax) {
                for (std::size_t v = 0; v < count; ++v) {
                    if (uniform(v)) continue;
                    const std::size_t b = start_[v];
                    const long long n = (long long)size_at(v);
                    scratch_.resize(std::size_t(n));
                    fw::sparsemax_weights<T>(logits_.data() + b, n, tau_[v], weights_out_ + b, scratch_.data());
                    stats_[v].kept = std::int32_t(fw::trim_weights<T>(weights_out_ + b, n, trim, scratch_.data()));
                    stats_[v].entropy = float(fw::weight_entropy<T>(weights_out_ + b, n));
                }
            } else {
                shifted_logits_.resize(total);
                for (std::size_t v = 0; v < count; ++v) {
                    const std::size_t b = start_[v];
                    if (uniform(v)) {
                        std::fill_n(shifted_logits_.data() + b, size_at(v), T(0));
                        continue;
                    }
                    fw::softmax_logits<T>(logits_.data() + b, (long long)size_at(v), tau_[v], shifted_logits_.data() + b);
                }
                fw::exp_nonpositive<T>(shifted_logits_.data(), (long long)total, weights_out_);
                for (std::size_t v = 0; v < count; ++v) {
                    if (uniform(v)) continue;
                    const std::size_t b = start_[v];
                    const long long n = (long long)size_at(v);
                    T entropy;
                    // Canonical order is by decreasing confidence, so the weights decrease.
                    stats_[v].kept = std::int32_t(fw::softmax_normalise_sorted<T>(weights_out_ + b, shifted_logits_.data() + b, n, trim, &entropy));
                    stats_[v].entropy = float(entropy);
                }
            }
        }
        for (std::size_t v = 0; v < count; ++v) {
            if (!uniform(v)) continue;
            const std::size_t n = size_at(v);
            std::fill_n(weights_out_ + start_[v], n, T(1) / T(n));
            stats_[v].kept = std::int32_t(n);
            stats_[v].entropy = (long long)n < kTable ? log_n_[n] : float(std::log(double(n)));
        }
    }

    std::size_t size(std::size_t v) const { return size_at(v - v0_); }
    const std::int32_t* ids(std::size_t v) const { return ids_out_ + start_[v - v0_]; }
    const float* positions(std::size_t v) const { return pos_.data() + 3 * start_[v - v0_]; }
    const T* weights(std::size_t v) const { return weights_out_ + start_[v - v0_]; }
    const VoxelStats& stats(std::size_t v) const { return stats_[v - v0_]; }

private:
    std::size_t size_at(std::size_t v) const { return start_[v + 1] - start_[v]; }

    // Copies the n samples with input indices ids[0..n) into ids_out_, pos_ and conf_ from slot
    // `start` on, in canonical order (canonical_order.h).
    void canonicalise(std::size_t start, const std::int32_t* ids, std::size_t n) {
        const bool has_conf = in_confidence_ != nullptr;
        // The voxel's positions and confidences, side by side in scratch memory.
        in_pos_.resize(3 * n);
        if (has_conf) in_conf_.resize(n);
        for (std::size_t k = 0; k < n; ++k) {
            const std::size_t i = std::size_t(ids[k]);
            in_pos_[3 * k] = in_positions_[3 * i];
            in_pos_[3 * k + 1] = in_positions_[3 * i + 1];
            in_pos_[3 * k + 2] = in_positions_[3 * i + 2];
            if (has_conf) in_conf_[k] = in_confidence_[i];
        }
        const VoxelSamples s{ids, in_pos_.data(), has_conf ? in_conf_.data() : nullptr, n};
        std::int32_t* out_ids = ids_out_ + start;
        float* out_pos = pos_.data() + 3 * start;
        float* out_conf = has_conf ? conf_.data() + start : nullptr;
        if (n == 1) {
            out_ids[0] = ids[0];
            std::copy_n(s.positions, 3, out_pos);
            if (has_conf) out_conf[0] = s.confidence[0];
            return;
        }
        canonical_order(s, ties_, order_);
        const std::int32_t* slots = order_.slots.data();
        for (std::size_t k = 0; k < n; ++k) {
            const std::size_t slot = std::size_t(slots[k]);
            out_ids[k] = ids[slot];
            out_pos[3 * k] = s.positions[3 * slot];
            out_pos[3 * k + 1] = s.positions[3 * slot + 1];
            out_pos[3 * k + 2] = s.positions[3 * slot + 2];
            if (has_conf) out_conf[k] = s.confidence[slot];
        }
    }

    // E|p - mu|^2 over block voxel v, two passes in double.
    double variance(std::size_t v) const {
        const std::size_t n = size_at(v);
        const float* pos = pos_.data() + 3 * start_[v];
        double mu[3] = {0.0, 0.0, 0.0};
        for (std::size_t k = 0; k < n; ++k)
            for (int a = 0; a < 3; ++a) mu[a] += double(pos[3 * k + a]);
        for (double& m : mu) m /= double(n);
        double sum = 0.0;
        for (std::size_t k = 0; k < n; ++k) {
            for (int a = 0; a < 3; ++a) {
                const double d = double(pos[3 * k + a]) - mu[a];
                sum += d * d;
            }
        }
        return sum / double(n);
    }

    const std::int32_t* samples_;
    const std::int64_t* offsets_;
    std::size_t voxels_;
    const TieFields& ties_;
    const FusionParams& params_;
    double voxel_size_;
    const float* in_positions_;
    const float* in_confidence_;
    std::int32_t* csr_ids_;
    T* csr_weights_;
    std::size_t v0_ = 0;
    std::int32_t* ids_out_ = nullptr;  // canonical ids of the block: csr_ids_ or ids_scratch_
    T* weights_out_ = nullptr;         // weights of the block: csr_weights_ or weights_scratch_
    std::vector<std::size_t> start_;       // block voxel -> first sample slot
    std::vector<float> in_pos_, in_conf_;  // one voxel, input order
    CanonicalScratch order_;               // one voxel's canonical order
    std::vector<std::int32_t> ids_scratch_;  // canonical ids when no CSR output is given
    std::vector<float> pos_, conf_;        // canonical order, whole block
    // Per sample of the block: confidence probabilities, logits, tempered shifted logits, and
    // the weights when no CSR output is given; per voxel: temperatures. scratch_: one voxel.
    std::vector<T> probability_, logits_, shifted_logits_, weights_scratch_, scratch_, tau_;
    std::vector<VoxelStats> stats_;
    static constexpr long long kTable = 64;
    T factor_[kTable] = {};
    float log_n_[kTable] = {};
};

inline void allocate_diagnostics(VoxelDiagnostics& d, std::size_t m) {
    d.occupancy.resize(m);
    d.temperature.resize(m);
    d.variance.resize(m);
    d.reliability.resize(m);
    d.kept.resize(m);
    d.entropy.resize(m);
}

inline void store_diagnostics(VoxelDiagnostics& d, std::size_t v, std::size_t n, const VoxelStats& s) {
    d.occupancy[v] = std::int32_t(n);
    d.temperature[v] = s.temperature;
    d.variance[v] = float(s.variance);
    d.reliability[v] = s.reliability;
    d.kept[v] = s.kept;
    d.entropy[v] = s.entropy;
}

}  // namespace avsplat::fusion_detail
