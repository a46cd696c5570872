#include "avsplat/fusion/fusion.h"
#include "fusion/voxel_weights.h"
#include "render/shared/tiling.h"

#include "common/cpu_dispatch.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace avsplat {

namespace {

namespace fw = fusion_weights;

constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();

// Below this many samples a loop runs on the calling thread: starting threads would cost more
// than it saves, and small calls stay fast when the cores are busy with other work.
constexpr std::size_t kParallelMin = std::size_t(1) << 14;

// Voxels weighed together by BlockWeigher: enough to overlap their short computations, few
// enough that a block's scratch memory stays in the L1 and L2 caches.
constexpr std::size_t kBlockVoxels = 32;

// ---------------------------------------------------------------------------------------------
// Canonical order of a voxel's samples

// A per-sample float row (width floats per sample, contiguous) that orders samples sharing a
// position and a confidence.
struct RowField {
    const float* data;
    std::size_t width;
};

// The fields that order samples sharing a position and a confidence, read by input index.
using TieFields = std::vector<RowField>;

inline std::uint32_t float_bits(float f) {
    std::uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
}

// A key whose unsigned order is the decreasing order of finite floats (-0 after +0): the
// complement of the renderer's order-preserving depth key. Never UINT32_MAX (that would be
// -inf), so rank_ascending16's pads stay last.
inline std::uint32_t descending_key(float f) { return ~tiling::depth_bits(f); }

inline int compare_bits(const float* a, const float* b, std::size_t n) {
    for (std::size_t k = 0; k < n; ++k) {
        const std::uint32_t x = float_bits(a[k]), y = float_bits(b[k]);
        if (x != y) return x < y ? -1 : 1;
    }
    return 0;
}

// One voxel's samples: input indices, and positions and confidences gathered contiguously.
struct VoxelSamples {
    const std::int32_t* ids;
    const float* positions;   // n x 3
    const float* confidence;  // n, or null
    std::size_t n;
};

// Bit-pattern order of local sample slots: a total order on the sample contents that does not
// depend on where the samples sit in the input. Samples equal in every field are
// interchangeable, so ordering them by index cannot change a result.
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

// Place of each of x[0..n) in increasing order, ties by position: rank[i] = #{j : x[j] < x[i]}
// + #{j < i : x[j] == x[i]}. x holds 16 values, padded with UINT32_MAX beyond n (never the bit
// pattern of a finite float, so a pad is never smaller than or equal to a value). On x86 the
// comparisons run in SSE2 registers (unsigned order via a flipped sign bit); the ranks are
// integers either way, so both paths give the same result.
void rank_ascending16(const std::uint32_t* x, int n, int* rank) {
#ifdef AVSPLAT_FUSION_SSE2
    const __m128i flip = _mm_set1_epi32(int(0x80000000u));
    const auto load = [&](int k) {
        return _mm_xor_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(x + k)), flip);
    };
    const __m128i c0 = load(0), c1 = load(4), c2 = load(8), c3 = load(12);
    const __m128i l0 = _mm_setr_epi32(0, 1, 2, 3), l1 = _mm_setr_epi32(4, 5, 6, 7),
                  l2 = _mm_setr_epi32(8, 9, 10, 11), l3 = _mm_setr_epi32(12, 13, 14, 15);
    for (int i = 0; i < n; ++i) {
        const __m128i v = _mm_set1_epi32(int(x[i] ^ 0x80000000u));
        const __m128i before = _mm_set1_epi32(i);
        __m128i count = _mm_cmplt_epi32(c0, v);  // masks are -1 where true
        count = _mm_add_epi32(count, _mm_cmplt_epi32(c1, v));
        count = _mm_add_epi32(count, _mm_cmplt_epi32(c2, v));
        count = _mm_add_epi32(count, _mm_cmplt_epi32(c3, v));
        count = _mm_add_epi32(count, _mm_and_si128(_mm_cmpeq_epi32(c0, v), _mm_cmplt_epi32(l0, before)));
        count = _mm_add_epi32(count, _mm_and_si128(_mm_cmpeq_epi32(c1, v), _mm_cmplt_epi32(l1, before)));
        count = _mm_add_epi32(count, _mm_and_si128(_mm_cmpeq_epi32(c2, v), _mm_cmplt_epi32(l2, before)));
        count = _mm_add_epi32(count, _mm_and_si128(_mm_cmpeq_epi32(c3, v), _mm_cmplt_epi32(l3, before)));
        count = _mm_add_epi32(count, _mm_shuffle_epi32(count, 0x4E));
        count = _mm_add_epi32(count, _mm_shuffle_epi32(count, 0xB1));
        rank[i] = -_mm_cvtsi128_si32(count);
    }
#else
    for (int i = 0; i < n; ++i) {
        int r = 0;
        for (int j = 0; j < 16; ++j) r += (x[j] < x[i]) + ((x[j] == x[i]) & (j < i));
        rank[i] = r;
    }
#endif
}

// Starts fetching the positions (and confidences) of samples ids[0..n): the per-voxel loops
// read them through the grid's sample indices, scattered over the input, so they ask for a
// voxel's samples a few voxels ahead.
inline void prefetch_samples(const std::int32_t* ids, std::size_t n, const float* positions, const float* confidence) {
    for (std::size_t k = 0; k < n; ++k) {
        const std::size_t i = std::size_t(ids[k]);
        __builtin_prefetch(positions + 3 * i);
        __builtin_prefetch(positions + 3 * i + 2);  // a position may straddle two cache lines
        if (confidence) __builtin_prefetch(confidence + i);
    }
}

// ---------------------------------------------------------------------------------------------
// Weights of one voxel

struct VoxelStats {
    double variance = 0.0;
    float temperature = 0.f;
    float reliability = 0.f;
    float entropy = 0.f;
    std::int32_t kept = 0;
};

// Per-thread worker: canonical order, weights and diagnostics of a block of consecutive voxels,
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
          p_(p),
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
            ids_at_ = csr_ids_ + offsets_[v0];
            w_at_ = csr_weights_ + offsets_[v0];
        } else {
            ids_.resize(total);
            w_.resize(total);
            ids_at_ = ids_.data();
            w_at_ = w_.data();
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
            q_.resize(total);
            bool mapped = false;
            if constexpr (std::is_same_v<T, float>) {
                if (p_.confidence_mapping == ConfidenceMapping::Logit) {
                    fw::sigmoid<float>(conf_.data(), (long long)total, q_.data());
                    mapped = true;
                }
            }
            if (!mapped)
                for (std::size_t k = 0; k < total; ++k) q_[k] = fw::confidence_probability<T>(conf_[k], p_.confidence_mapping);
        }
        for (std::size_t v = 0; v < count; ++v) {
            const std::size_t n = size_at(v);
            double mean_q = 0.5;
            if (has_conf) {
                double sum_q = 0.0;
                for (std::size_t k = start_[v]; k < start_[v + 1]; ++k) sum_q += double(q_[k]);
                mean_q = sum_q / double(n);
            }
            const T g = fw::geometric_consistency<T>(T(stats_[v].variance), T(voxel_size_), T(p_.eps));
            const T r = fw::reliability<T>(T(mean_q), g, T(p_.b_conf), T(p_.b_geo), T(p_.eps));
            VoxelStats& st = stats_[v];
            st.reliability = float(r);
            switch (p_.policy) {
                case FusionPolicy::Mean:
                    tau_[v] = std::numeric_limits<T>::infinity();
                    break;
                case FusionPolicy::Softmax:
                    tau_[v] = T(1);
                    break;
                case FusionPolicy::Occupancy: {
                    const T factor = (long long)n < kTable ? factor_[n]
                                                           : fw::temperature_factor<T>((long long)n, T(p_.tau0), T(p_.alpha),
                                                                                       T(p_.n_ref), T(p_.eps));
                    tau_[v] = fw::temperature_from_factor<T>(factor, r, T(p_.tau_min), T(p_.tau_max), T(p_.k_rel));
                    break;
                }
            }
            st.temperature = float(tau_[v]);
        }

        // Without confidence (or with one sample) all logits are equal: every policy gives the
        // plain average, and trimming keeps ties. Other voxels: softmax (AnySplat: of the raw
        // confidence, whatever the mapping) or the occupancy policy's softmax or sparsemax.
        const auto uniform = [&](std::size_t v) {
            return !has_conf || size_at(v) == 1 || p_.policy == FusionPolicy::Mean;
        };
        if (has_conf && p_.policy != FusionPolicy::Mean) {
            logits_.resize(total);
            if (p_.policy == FusionPolicy::Softmax || p_.confidence_mapping == ConfidenceMapping::Logit)
                for (std::size_t k = 0; k < total; ++k) logits_[k] = T(conf_[k]);
            else
                for (std::size_t k = 0; k < total; ++k) logits_[k] = fw::confidence_logit<T>(conf_[k], p_.confidence_mapping);
            const double trim = p_.policy == FusionPolicy::Occupancy ? p_.trim_mass : 0.0;
            if (p_.policy == FusionPolicy::Occupancy && p_.weights == WeightFunction::Sparsemax) {
                for (std::size_t v = 0; v < count; ++v) {
                    if (uniform(v)) continue;
                    const std::size_t b = start_[v];
                    const long long n = (long long)size_at(v);
                    scratch_.resize(std::size_t(n));
                    fw::sparsemax_weights<T>(logits_.data() + b, n, tau_[v], w_at_ + b, scratch_.data());
                    stats_[v].kept = std::int32_t(fw::trim_weights<T>(w_at_ + b, n, trim, scratch_.data()));
                    stats_[v].entropy = float(fw::weight_entropy<T>(w_at_ + b, n));
                }
            } else {
                z_.resize(total);
                for (std::size_t v = 0; v < count; ++v) {
                    const std::size_t b = start_[v];
                    if (uniform(v)) {
                        std::fill_n(z_.data() + b, size_at(v), T(0));
                        continue;
                    }
                    fw::softmax_logits<T>(logits_.data() + b, (long long)size_at(v), tau_[v], z_.data() + b);
                }
                fw::exp_nonpositive<T>(z_.data(), (long long)total, w_at_);
                for (std::size_t v = 0; v < count; ++v) {
                    if (uniform(v)) continue;
                    const std::size_t b = start_[v];
                    const long long n = (long long)size_at(v);
                    T entropy;
                    // Canonical order is by decreasing confidence, so the weights decrease.
                    stats_[v].kept = std::int32_t(fw::softmax_normalise_sorted<T>(w_at_ + b, z_.data() + b, n, trim, &entropy));
                    stats_[v].entropy = float(entropy);
                }
            }
        }
        for (std::size_t v = 0; v < count; ++v) {
            if (!uniform(v)) continue;
            const std::size_t n = size_at(v);
            std::fill_n(w_at_ + start_[v], n, T(1) / T(n));
            stats_[v].kept = std::int32_t(n);
            stats_[v].entropy = (long long)n < kTable ? log_n_[n] : float(std::log(double(n)));
        }
    }

    std::size_t size(std::size_t v) const { return size_at(v - v0_); }
    const std::int32_t* ids(std::size_t v) const { return ids_at_ + start_[v - v0_]; }
    const float* positions(std::size_t v) const { return pos_.data() + 3 * start_[v - v0_]; }
    const T* weights(std::size_t v) const { return w_at_ + start_[v - v0_]; }
    const VoxelStats& stats(std::size_t v) const { return stats_[v - v0_]; }

private:
    std::size_t size_at(std::size_t v) const { return start_[v + 1] - start_[v]; }

    // Copies the n samples with input indices ids[0..n) into ids_, pos_ and conf_ from slot
    // `start` on, in canonical order (CanonicalLess).
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
        std::int32_t* out_ids = ids_at_ + start;
        float* out_pos = pos_.data() + 3 * start;
        float* out_conf = has_conf ? conf_.data() + start : nullptr;
        if (n == 1) {
            out_ids[0] = ids[0];
            std::copy_n(s.positions, 3, out_pos);
            if (has_conf) out_conf[0] = s.confidence[0];
            return;
        }
        // Order by decreasing confidence (without confidence: by the bits of x), then resolve
        // runs of equal keys with the full canonical comparison. Ordered by confidence, the
        // weights decrease along the voxel, so trimming needs no sort. The few samples of a
        // typical voxel are ranked by counting (no unpredictable branch; up to 16 in SSE2
        // registers), larger voxels by sorting (key, slot) integers.
        xbits_.resize(std::max<std::size_t>(n, 16));
        slots_.resize(n);
        if (has_conf)
            for (std::size_t k = 0; k < n; ++k) xbits_[k] = descending_key(s.confidence[k]);
        else
            for (std::size_t k = 0; k < n; ++k) xbits_[k] = float_bits(s.positions[3 * k]);
        if (n <= 16) {
            std::fill(xbits_.begin() + std::ptrdiff_t(n), xbits_.begin() + 16, ~std::uint32_t(0));
            int rank[16];
            rank_ascending16(xbits_.data(), int(n), rank);
            for (int i = 0; i < int(n); ++i) slots_[std::size_t(rank[i])] = i;
        } else {
            // (key, slot) packed in one integer: a plain integer sort, ties by slot.
            keyed_.resize(n);
            for (std::size_t k = 0; k < n; ++k) keyed_[k] = (std::uint64_t(xbits_[k]) << 32) | std::uint64_t(k);
            std::sort(keyed_.begin(), keyed_.end());
            for (std::size_t k = 0; k < n; ++k) slots_[k] = std::int32_t(keyed_[k] & 0xFFFFFFFFu);
        }
        for (std::size_t i = 0; i < n;) {
            std::size_t j = i + 1;
            const std::uint32_t xi = xbits_[std::size_t(slots_[i])];
            while (j < n && xbits_[std::size_t(slots_[j])] == xi) ++j;
            if (j - i > 1) std::sort(slots_.begin() + std::ptrdiff_t(i), slots_.begin() + std::ptrdiff_t(j), CanonicalLess{&s, &ties_});
            i = j;
        }
        for (std::size_t k = 0; k < n; ++k) {
            const std::size_t slot = std::size_t(slots_[k]);
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
    const FusionParams& p_;
    double voxel_size_;
    const float* in_positions_;
    const float* in_confidence_;
    std::int32_t* csr_ids_;
    T* csr_weights_;
    std::size_t v0_ = 0;
    std::int32_t* ids_at_ = nullptr;  // canonical ids of the block: csr_ids_ or ids_
    T* w_at_ = nullptr;               // weights of the block: csr_weights_ or w_
    std::vector<std::size_t> start_;       // block voxel -> first sample slot
    std::vector<float> in_pos_, in_conf_;  // one voxel, input order
    std::vector<std::uint32_t> xbits_;
    std::vector<std::uint64_t> keyed_;
    std::vector<std::int32_t> slots_, ids_;
    std::vector<float> pos_, conf_;        // canonical order, whole block
    std::vector<T> q_, logits_, z_, w_, scratch_, tau_;
    std::vector<VoxelStats> stats_;
    static constexpr long long kTable = 64;
    T factor_[kTable] = {};
    float log_n_[kTable] = {};
};

void allocate_diagnostics(VoxelDiagnostics& d, std::size_t m) {
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

// Starts fetching a feature row. Each row is read once, so it is fetched non-temporally (x86
// prefetchnta): it does not push the positions, indices and weights out of the outer caches.
inline void prefetch_row(const float* row, std::size_t floats) {
    const char* p = reinterpret_cast<const char*>(row);
    const char* end = p + floats * sizeof(float);
    for (; p < end; p += 64) __builtin_prefetch(p, 0, 0);
    __builtin_prefetch(end - 1, 0, 0);
}

// out[c] = float(inv * sum_k w[k] * rows[ids[k] * width + c]) for c < width, summed in double
// over k in order; returns whether every out[c] is finite. Blocks of 16 channels stay in
// registers across the voxel's samples (the rows stay in L1), so the accumulators are never
// reloaded; each channel is still summed in sample order, whatever the block.
// Built for x86-64-v3 and the baseline (cpu_dispatch.h).
AVSPLAT_CLONES_V3
bool weighted_rows(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                   const double* __restrict w, std::size_t n, double inv, float* __restrict out) {
    constexpr std::size_t kBlock = 16;
    bool ok = true;
    std::size_t c0 = 0;
    for (; c0 + kBlock <= width; c0 += kBlock) {
        double a[kBlock] = {};
        for (std::size_t k = 0; k < n; ++k) {
            const float* r = rows + width * std::size_t(ids[k]) + c0;
            const double wk = w[k];
            for (std::size_t j = 0; j < kBlock; ++j) a[j] += wk * double(r[j]);
        }
        for (std::size_t j = 0; j < kBlock; ++j) {
            out[c0 + j] = float(a[j] * inv);
            ok &= std::isfinite(out[c0 + j]);
        }
    }
    if (c0 < width) {
        const std::size_t rest = width - c0;
        double a[kBlock] = {};
        for (std::size_t k = 0; k < n; ++k) {
            const float* r = rows + width * std::size_t(ids[k]) + c0;
            const double wk = w[k];
            for (std::size_t j = 0; j < rest; ++j) a[j] += wk * double(r[j]);
        }
        for (std::size_t j = 0; j < rest; ++j) {
            out[c0 + j] = float(a[j] * inv);
            ok &= std::isfinite(out[c0 + j]);
        }
    }
    return ok;
}

// ---------------------------------------------------------------------------------------------
// Input checks

std::string format_float(float v) {
    std::ostringstream os;
    os.precision(9);
    os << v;
    return os.str();
}

const char* mapping_name(ConfidenceMapping m) {
    switch (m) {
        case ConfidenceMapping::Probability: return "probability";
        case ConfidenceMapping::Positive: return "positive";
        default: return "logit";
    }
}

std::string confidence_error(const char* field, std::size_t i, float c, ConfidenceMapping m) {
    std::string what;
    if (!std::isfinite(c)) what = "NaN or Inf";
    else if (m == ConfidenceMapping::Probability) what = "outside [0, 1]";
    else what = "negative";
    return std::string(field) + "[" + std::to_string(i) + "] = " + format_float(c) + ": " + what +
           " (confidence_mapping " + mapping_name(m) + "; pass on_invalid=drop to drop such samples)";
}

// First index in [0, n) for which bad(i) holds, or kNone; parallel, deterministic.
template <class Bad>
std::size_t first_bad_index(std::size_t n, Bad bad) {
    std::size_t first = kNone;
#pragma omp parallel if (n >= kParallelMin)
    {
        const std::size_t threads = std::size_t(omp_get_num_threads()), t = std::size_t(omp_get_thread_num());
        const std::size_t b = n * t / threads, e = n * (t + 1) / threads;
        std::size_t mine = kNone;
        for (std::size_t i = b; i < e; ++i) {
            if (bad(i)) {
                mine = i;
                break;
            }
        }
#pragma omp critical(avsplat_first_bad)
        first = std::min(first, mine);
    }
    return first;
}

// Checks the confidence against its mapping. Raise: throws at the first invalid one. Drop: clears
// keep[i] for every invalid one (keep is allocated on first use). Returns whether any was bad.
bool check_confidence(const float* conf, std::size_t n, const FusionParams& p, const char* field,
                      std::vector<std::uint8_t>& keep) {
    if (!conf) return false;
    const auto bad = [&](std::size_t i) { return !fw::confidence_valid(conf[i], p.confidence_mapping); };
    const std::size_t first = first_bad_index(n, bad);
    if (first == kNone) return false;
    if (p.on_invalid == InvalidPolicy::Raise)
        throw std::invalid_argument(confidence_error(field, first, conf[first], p.confidence_mapping));
    if (keep.empty()) keep.assign(n, 1);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
    for (std::int64_t i = std::int64_t(first); i < std::int64_t(n); ++i)
        if (bad(std::size_t(i))) keep[std::size_t(i)] = 0;
    return true;
}

}  // namespace

// -------------------------------------------------------------------------------------------------
// Parameters

void validate(const FusionParams& p) {
    const auto fail = [](const char* field, double v, const char* want) {
        std::ostringstream os;
        os << "FusionParams." << field << ": " << v << " is invalid; expected " << want;
        throw std::invalid_argument(os.str());
    };
    const auto finite = [](double v) { return std::isfinite(v); };
    if (!(finite(p.tau0) && p.tau0 > 0)) fail("tau0", p.tau0, "a finite value > 0");
    if (!(finite(p.alpha) && p.alpha >= 0)) fail("alpha", p.alpha, "a finite value >= 0");
    if (!(finite(p.n_ref) && p.n_ref > 0)) fail("n_ref", p.n_ref, "a finite value > 0");
    if (!(finite(p.tau_min) && p.tau_min > 0)) fail("tau_min", p.tau_min, "a finite value > 0");
    if (!(finite(p.tau_max) && p.tau_max >= p.tau_min)) fail("tau_max", p.tau_max, "a finite value >= tau_min");
    if (!(finite(p.b_conf) && p.b_conf >= 0)) fail("b_conf", p.b_conf, "a finite value >= 0");
    if (!(finite(p.b_geo) && p.b_geo >= 0)) fail("b_geo", p.b_geo, "a finite value >= 0");
    if (!(finite(p.k_rel) && p.k_rel >= 0)) fail("k_rel", p.k_rel, "a finite value >= 0");
    if (!(finite(p.eps) && p.eps >= 0)) fail("eps", p.eps, "a finite value >= 0");
    if (!(p.b_conf + p.b_geo + p.eps > 0)) fail("b_conf", p.b_conf, "b_conf + b_geo + eps > 0");
    if (!(p.trim_mass >= 0 && p.trim_mass <= 1)) fail("trim_mass", p.trim_mass, "a value in [0, 1] (0: off)");
    const auto enum_ok = [](auto e, int count) { return int(e) >= 0 && int(e) < count; };
    if (!enum_ok(p.policy, 3)) fail("policy", double(int(p.policy)), "Mean, Softmax or Occupancy");
    if (!enum_ok(p.weights, 2)) fail("weights", double(int(p.weights)), "Softmax or Sparsemax");
    if (!enum_ok(p.confidence_mapping, 3))
        fail("confidence_mapping", double(int(p.confidence_mapping)), "Logit, Probability or Positive");
    if (!enum_ok(p.shape, 2)) fail("shape", double(int(p.shape)), "Average or Moment");
    if (!enum_ok(p.on_invalid, 2)) fail("on_invalid", double(int(p.on_invalid)), "Raise or Drop");
    if (!enum_ok(p.precision, 2)) fail("precision", double(int(p.precision)), "Float32 or Float64");
}

// -------------------------------------------------------------------------------------------------
// Feature fusion

namespace {

// Fuses every voxel of `grid`. Returns false when some voxel met a non-finite feature (the
// output is then incomplete and the caller finds and handles the bad sample).
template <class T>
bool fuse_features_pass(const SparseVoxelGrid& grid, const float* positions, const float* confidence,
                        const float* features, std::size_t channels, const FusionParams& p,
                        FeatureFusionResult& out) {
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
        detail::advise_huge_pages(canonical_ids.get(), total * sizeof(std::int32_t));
        detail::advise_huge_pages(canonical_weights.get(), total * sizeof(T));
    }
    std::int32_t* cids = canonical_ids.get();
    T* cw = canonical_weights.get();
    TieFields ties;
    if (channels) ties.push_back({features, channels});

    // Pass 1: weights, diagnostics and fused positions. Meanwhile one thread allocates and
    // zero-fills the feature output, a serial memset that would otherwise hold up every thread.
    const std::int64_t blocks = std::int64_t((m + kBlockVoxels - 1) / kBlockVoxels);
#pragma omp parallel if (parallel)
    {
#pragma omp single nowait
        {
            detail::reserve_huge(out.features, m * channels);
            out.features.resize(m * channels);
        }
        BlockWeigher<T> weigher(grid, ties, p, positions, confidence, cids, cw);
#pragma omp for schedule(dynamic, 2)
        for (std::int64_t block = 0; block < blocks; ++block) {
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
        }
    }
    if (!channels) return true;

    // Pass 2: the weighted feature rows. The rows are scattered over the input: the loop starts
    // fetching those of the voxel after next, so that they arrive while this one and the next
    // are fused.
    bool finite = true;
#pragma omp parallel reduction(&& : finite) if (parallel)
    {
        std::vector<double> wd;
#pragma omp for schedule(dynamic, 64)
        for (std::int64_t vv = 0; vv < std::int64_t(m); ++vv) {
            const std::size_t v = std::size_t(vv);
            const std::size_t b = std::size_t(offsets[v]);
            const std::size_t n = std::size_t(offsets[v + 1]) - b;
            if (v + 2 < m)
                for (std::int64_t j = offsets[v + 2]; j < offsets[v + 3]; ++j)
                    prefetch_row(features + channels * std::size_t(cids[j]), channels);
            float* out_f = out.features.data() + channels * v;
            if (n == 1) {
                std::copy_n(features + channels * std::size_t(cids[b]), channels, out_f);
                for (std::size_t c = 0; c < channels; ++c) finite = finite && std::isfinite(out_f[c]);
                continue;
            }
            wd.resize(n);
            double wsum = 0.0;  // the same sum as pass 1's, so the same 1 / wsum
            for (std::size_t k = 0; k < n; ++k) {
                wd[k] = double(cw[b + k]);
                wsum += wd[k];
            }
            // Zero weights still accumulate, so that a NaN/Inf anywhere shows in the sums.
            finite = weighted_rows(features, channels, cids + b, wd.data(), n, 1.0 / wsum, out_f) && finite;
        }
    }
    return finite;
}

template <class T>
FeatureFusionResult fuse_features(const float* positions, std::size_t n, const float* features,
                                  std::size_t channels, double voxel_size, const float* confidence,
                                  const FusionParams& p) {
    std::vector<std::uint8_t> keep;
    check_confidence(confidence, n, p, "confidence", keep);
    FeatureFusionResult out;
    out.channels = int(channels);
    for (int attempt = 0; attempt < 2; ++attempt) {
        SparseVoxelGrid grid(positions, n, voxel_size, p.on_invalid, keep.empty() ? nullptr : keep.data(),
                             "positions");
        if (fuse_features_pass<T>(grid, positions, confidence, features, channels, p, out)) {
            out.dropped = grid.dropped();
            out.voxel_coords = std::move(grid).voxel_coords();
            out.sample_voxel = std::move(grid).sample_voxel();
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
        const std::size_t first = first_bad_index(n, bad_row);
        if (first == kNone) break;  // cannot happen: the sums are finite for finite inputs
        if (p.on_invalid == InvalidPolicy::Raise) {
            const float* f = features + channels * first;
            std::size_t c = 0;
            while (std::isfinite(f[c])) ++c;
            throw std::invalid_argument("features[" + std::to_string(first) + ", " + std::to_string(c) +
                                        "] = " + format_float(f[c]) +
                                        ": NaN or Inf (pass on_invalid=drop to drop such samples)");
        }
        if (keep.empty()) keep.assign(n, 1);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
        for (std::int64_t i = std::int64_t(first); i < std::int64_t(n); ++i)
            if (bad_row(std::size_t(i))) keep[std::size_t(i)] = 0;
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

// -------------------------------------------------------------------------------------------------
// Gaussian fusion

namespace {

void check_cloud_shapes(const GaussianCloud& c) {
    if (c.sh_degree < 0 || c.sh_degree > kMaxShDegree)
        throw std::invalid_argument("GaussianCloud.sh_degree: " + std::to_string(c.sh_degree) +
                                    " is not a supported SH degree (0..3)");
    const std::size_t n = c.size();
    const auto check = [](const char* field, std::size_t got, std::size_t want) {
        if (got != want)
            throw std::invalid_argument(std::string("GaussianCloud.") + field + ": expected " +
                                        std::to_string(want) + " floats, got " + std::to_string(got));
    };
    check("means", c.means.size(), 3 * n);
    check("scales", c.scales.size(), 3 * n);
    check("rotations", c.rotations.size(), 4 * n);
    check("sh", c.sh.size(), n * std::size_t(c.sh_coeffs()) * 3);
    if (c.has_confidence()) check("confidence", c.confidence.size(), n);
    for (const auto& e : c.extras) check(("extras['" + e.name + "']").c_str(), e.values.size(), n);
}

// What validate(GaussianCloud) accepts, per Gaussian (used to drop instead of throwing).
bool gaussian_valid(const GaussianCloud& c, std::size_t i) {
    const auto finite = [](const float* p, std::size_t k) {
        for (std::size_t j = 0; j < k; ++j)
            if (!std::isfinite(p[j])) return false;
        return true;
    };
    const std::size_t k = std::size_t(c.sh_coeffs()) * 3;
    const float* s = &c.scales[3 * i];
    const float* q = &c.rotations[4 * i];
    if (!finite(&c.means[3 * i], 3) || !finite(s, 3) || !finite(q, 4) || !finite(&c.opacities[i], 1) ||
        !finite(c.sh.data() + k * i, k))
        return false;
    for (const auto& e : c.extras)
        if (!std::isfinite(e.values[i])) return false;
    if (s[0] < 0.f || s[1] < 0.f || s[2] < 0.f) return false;
    if (q[0] == 0.f && q[1] == 0.f && q[2] == 0.f && q[3] == 0.f) return false;
    return c.opacities[i] >= 0.f && c.opacities[i] <= 1.f;
}

// Unit quaternion (w, x, y, z) with w >= 0 stored as float.
void store_quaternion(Eigen::Vector4d q, float* out) {
    q.normalize();
    if (q[0] < 0.0) q = -q;
    for (int a = 0; a < 4; ++a) out[a] = float(q[a]);
}

template <class T>
void fuse_gaussians_pass(const SparseVoxelGrid& grid, const TieFields& ties, const GaussianCloud& in,
                         const FusionParams& p, GaussianFusionResult& result) {
    const std::size_t m = grid.num_voxels();
    const std::size_t k3 = std::size_t(in.sh_coeffs()) * 3;
    GaussianCloud& out = result.cloud;
    out = GaussianCloud(m, in.sh_degree);
    if (in.has_confidence()) out.confidence.resize(m);
    out.extras.clear();
    for (const auto& e : in.extras) out.extras.push_back({e.name, std::vector<float>(m)});
    allocate_diagnostics(result.diagnostics, m);
    const float* conf_in = in.has_confidence() ? in.confidence.data() : nullptr;
    const std::int64_t* offsets = grid.voxel_offsets().data();
    const std::int64_t blocks = std::int64_t((m + kBlockVoxels - 1) / kBlockVoxels);
#pragma omp parallel if (grid.sample_indices().size() >= kParallelMin)
    {
        BlockWeigher<T> weigher(grid, ties, p, in.means.data(), conf_in);
        std::vector<double> wd, extra_acc(in.extras.size());
#pragma omp for schedule(dynamic, 2)
        for (std::int64_t block = 0; block < blocks; ++block) {
            const std::size_t v0 = std::size_t(block) * kBlockVoxels, v1 = std::min(m, v0 + kBlockVoxels);
            weigher.run(v0, v1);
            for (std::size_t v = v0; v < v1; ++v) {
                const std::int64_t b = offsets[v];
                const std::size_t n = std::size_t(offsets[v + 1] - b);
                store_diagnostics(result.diagnostics, v, n, weigher.stats(v));
                if (n == 1) {
                    const std::size_t i = std::size_t(weigher.ids(v)[0]);
                    std::copy_n(&in.means[3 * i], 3, &out.means[3 * v]);
                    std::copy_n(&in.scales[3 * i], 3, &out.scales[3 * v]);
                    std::copy_n(&in.rotations[4 * i], 4, &out.rotations[4 * v]);
                    out.opacities[v] = in.opacities[i];
                    std::copy_n(in.sh.data() + k3 * i, k3, out.sh.data() + k3 * v);
                    if (in.has_confidence()) out.confidence[v] = in.confidence[i];
                    for (std::size_t e = 0; e < in.extras.size(); ++e) out.extras[e].values[v] = in.extras[e].values[i];
                    continue;
                }
                const std::int32_t* ids = weigher.ids(v);
                const T* w = weigher.weights(v);
                wd.resize(n);
                double wsum = 0.0, opacity = 0.0, conf = 0.0;
                Eigen::Vector3d mean = Eigen::Vector3d::Zero();
                std::fill(extra_acc.begin(), extra_acc.end(), 0.0);
                std::size_t leader = 0;  // highest weight, first in canonical order on ties
                for (std::size_t k = 0; k < n; ++k) {
                    const double wk = wd[k] = double(w[k]);
                    if (w[k] > w[leader]) leader = k;
                    const std::size_t i = std::size_t(ids[k]);
                    wsum += wk;
                    mean += wk * in.mean(i).cast<double>();
                    opacity += wk * double(in.opacities[i]);
                    if (in.has_confidence()) conf += wk * double(in.confidence[i]);
                    for (std::size_t e = 0; e < in.extras.size(); ++e) extra_acc[e] += wk * double(in.extras[e].values[i]);
                }
                const double inv = 1.0 / wsum;
                mean *= inv;
                for (int a = 0; a < 3; ++a) out.means[3 * v + a] = float(mean[a]);
                out.opacities[v] = float(std::min(1.0, std::max(0.0, opacity * inv)));
                if (in.has_confidence()) out.confidence[v] = float(conf * inv);
                weighted_rows(in.sh.data(), k3, ids, wd.data(), n, inv, out.sh.data() + k3 * v);
                for (std::size_t e = 0; e < in.extras.size(); ++e) out.extras[e].values[v] = float(extra_acc[e] * inv);

                if (p.shape == ShapeMode::Moment) {
                    Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();
                    for (std::size_t k = 0; k < n; ++k) {
                        if (!(w[k] > T(0))) continue;
                        const std::size_t i = std::size_t(ids[k]);
                        const Eigen::Vector3d d = in.mean(i).cast<double>() - mean;
                        sigma += double(w[k]) * (in.covariance(i) + d * d.transpose());
                    }
                    sigma *= inv;
                    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sigma);
                    Eigen::Matrix3d r = eig.eigenvectors();
                    if (r.determinant() < 0.0) r.col(0) = -r.col(0);
                    const Eigen::Quaterniond q(r);
                    for (int a = 0; a < 3; ++a) out.scales[3 * v + a] = float(std::sqrt(std::max(0.0, eig.eigenvalues()[a])));
                    store_quaternion(Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()), &out.rotations[4 * v]);
                } else {
                    // Weighted geometric mean of the scales (log 0 = -inf gives 0, never NaN: zero
                    // weights are skipped) and the hemisphere-aligned quaternion mean.
                    Eigen::Vector3d log_scale = Eigen::Vector3d::Zero();
                    Eigen::Vector4d quat = Eigen::Vector4d::Zero();
                    const Eigen::Vector4d ref = in.rotation(std::size_t(ids[leader])).cast<double>().normalized();
                    for (std::size_t k = 0; k < n; ++k) {
                        if (!(w[k] > T(0))) continue;
                        const std::size_t i = std::size_t(ids[k]);
                        const double wk = double(w[k]);
                        for (int a = 0; a < 3; ++a) log_scale[a] += wk * std::log(double(in.scales[3 * i + a]));
                        Eigen::Vector4d q = in.rotation(i).cast<double>().normalized();
                        if (q.dot(ref) < 0.0) q = -q;
                        quat += wk * q;
                    }
                    for (int a = 0; a < 3; ++a) out.scales[3 * v + a] = float(std::exp(log_scale[a] * inv));
                    store_quaternion(quat, &out.rotations[4 * v]);
                }
            }
        }
    }
}

template <class T>
GaussianFusionResult fuse_cloud(const GaussianCloud& cloud, double voxel_size, const FusionParams& p) {
    check_cloud_shapes(cloud);
    const std::size_t n = cloud.size();
    std::vector<std::uint8_t> keep;
    if (p.on_invalid == InvalidPolicy::Raise) {
        validate(cloud);
    } else {
        const auto bad = [&](std::size_t i) { return !gaussian_valid(cloud, i); };
        const std::size_t first = first_bad_index(n, bad);
        if (first != kNone) {
            keep.assign(n, 1);
#pragma omp parallel for schedule(static) if (n >= kParallelMin)
            for (std::int64_t i = std::int64_t(first); i < std::int64_t(n); ++i)
                if (bad(std::size_t(i))) keep[std::size_t(i)] = 0;
        }
    }
    const float* conf = cloud.has_confidence() ? cloud.confidence.data() : nullptr;
    check_confidence(conf, n, p, "GaussianCloud.confidence", keep);

    TieFields ties;
    ties.push_back({cloud.opacities.data(), 1});
    ties.push_back({cloud.scales.data(), 3});
    ties.push_back({cloud.rotations.data(), 4});
    ties.push_back({cloud.sh.data(), std::size_t(cloud.sh_coeffs()) * 3});
    for (const auto& e : cloud.extras) ties.push_back({e.values.data(), 1});

    SparseVoxelGrid grid(cloud.means.data(), n, voxel_size, p.on_invalid, keep.empty() ? nullptr : keep.data(),
                         "GaussianCloud.means");
    GaussianFusionResult result;
    fuse_gaussians_pass<T>(grid, ties, cloud, p, result);
    result.dropped = grid.dropped();
    result.voxel_coords = std::move(grid).voxel_coords();
    result.sample_voxel = std::move(grid).sample_voxel();
    return result;
}

}  // namespace

GaussianFusionResult fuse_gaussians(const GaussianCloud& cloud, double voxel_size, const FusionParams& params) {
    validate(params);
    if (params.precision == Precision::Float64) return fuse_cloud<double>(cloud, voxel_size, params);
    return fuse_cloud<float>(cloud, voxel_size, params);
}

}  // namespace avsplat
