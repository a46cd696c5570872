#include "avsplat/fusion/voxel_grid.h"

#include "common/cpu_dispatch.h"
#include "common/huge_pages.h"
#include "core/interrupt_poll.h"
#include "common/parallel.h"
#include "common/radix_sort.h"

#include <omp.h>
#include <parallel/algorithm>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

// round(x) fits int32 exactly when x lies strictly inside these bounds.
constexpr double kKeyLow = -2147483648.5;
constexpr double kKeyHigh = 2147483647.5;

// Round half away from zero (std::round) for |x| < 2^31. Truncation through int64 and the
// exact difference x - trunc(x) avoid a libm call per coordinate; the result is identical.
inline std::int32_t round_key(double x) {
    const std::int64_t t = static_cast<std::int64_t>(x);
    const double frac = x - static_cast<double>(t);  // exact: |x| < 2^31
    return static_cast<std::int32_t>(t + (frac >= 0.5) - (frac <= -0.5));
}

// round(x / voxel) exactly as documented (division in double), at the cost of a multiplication:
// x * inv differs from x / voxel by under 5e-7 while |x / voxel| < 2^31 (two roundings of at most
// half an ulp), so it decides the rounding unless its fraction lies within 1e-6 of a half, where
// the division is redone.
inline std::int32_t key_of(double x, double voxel, double inv) {
    const double q = x * inv;
    const std::int64_t t = static_cast<std::int64_t>(q);
    const double frac = q - static_cast<double>(t);
    if (std::abs(std::abs(frac) - 0.5) < 1e-6) return round_key(x / voxel);
    return static_cast<std::int32_t>(t + (frac >= 0.5) - (frac <= -0.5));
}

// Packs (key - key_lo, index) of samples [b, e) into out[0..e - b), the axes' fields at
// shift[a], with key_of's arithmetic but no branch, so that the loop vectorises (AVX2 through
// AVSPLAT_CLONES_V3). Returns non-zero when some coordinate's fraction lies within 1e-6 of a
// half, where key_of divides instead: the caller then recomputes this range with key_of. Needs
// |p / voxel| < 2^31 (checked on the bounding box) and shift[a] = 0 for an axis of one key.
AVSPLAT_CLONES_V3
int pack_keys(const float* __restrict positions, std::size_t b, std::size_t e, double inv_voxel,
              const std::int32_t* key_lo, const int* shift, std::uint64_t* __restrict out) {
    const std::int32_t lo0 = key_lo[0], lo1 = key_lo[1], lo2 = key_lo[2];
    const int s0 = shift[0], s1 = shift[1], s2 = shift[2];
    int near_half = 0;
    for (std::size_t i = b; i < e; ++i) {
        const float* p = positions + 3 * i;
        const double q0 = double(p[0]) * inv_voxel, q1 = double(p[1]) * inv_voxel, q2 = double(p[2]) * inv_voxel;
        const std::int32_t t0 = std::int32_t(q0), t1 = std::int32_t(q1), t2 = std::int32_t(q2);
        const double f0 = q0 - double(t0), f1 = q1 - double(t1), f2 = q2 - double(t2);
        near_half |= (std::fabs(std::fabs(f0) - 0.5) < 1e-6) | (std::fabs(std::fabs(f1) - 0.5) < 1e-6) |
                     (std::fabs(std::fabs(f2) - 0.5) < 1e-6);
        const std::int32_t k0 = t0 + (f0 >= 0.5) - (f0 <= -0.5);
        const std::int32_t k1 = t1 + (f1 >= 0.5) - (f1 <= -0.5);
        const std::int32_t k2 = t2 + (f2 >= 0.5) - (f2 <= -0.5);
        out[i - b] = (std::uint64_t(std::uint32_t(k0 - lo0)) << s0) | (std::uint64_t(std::uint32_t(k1 - lo1)) << s1) |
                     (std::uint64_t(std::uint32_t(k2 - lo2)) << s2) | std::uint64_t(i);
    }
    return near_half;
}

int bit_width(std::uint64_t v) {
    int b = 0;
    while (v) {
        ++b;
        v >>= 1;
    }
    return b;
}

inline std::uint64_t shift_left(std::uint64_t v, int s) { return s >= 64 ? 0 : v << s; }
inline std::uint64_t low_mask(int bits) { return bits >= 64 ? ~0ull : (1ull << bits) - 1; }

// The first invalid coordinate a thread met (index SIZE_MAX: none).
struct BadCoordinate {
    std::size_t index = std::numeric_limits<std::size_t>::max();
    int axis = 0;
    float value = 0.f;
    bool overflow = false;
};

struct PointBox {
    float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                   std::numeric_limits<float>::infinity()};
    float hi[3] = {-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                   -std::numeric_limits<float>::infinity()};
};

[[noreturn]] void throw_bad_coordinate(const BadCoordinate& b, double voxel_size, const char* name) {
    std::ostringstream os;
    os.precision(9);
    os << name << "[" << b.index << ", " << b.axis << "] = " << b.value << ": ";
    if (b.overflow) {
        os << "key round(p / voxel_size) = " << std::round(static_cast<double>(b.value) / voxel_size)
           << " does not fit int32 (voxel_size " << voxel_size
           << "); use a larger voxel or shift the scene towards the origin";
    } else {
        os << "NaN or Inf (pass on_invalid=drop to drop such samples)";
    }
    throw std::invalid_argument(os.str());
}

// CSR grouping of m sorted samples. same(j): sample j lies in the voxel of sample j - 1;
// index_at(j): its input index; coords_at(j, out): its key.
template <class Same, class IndexAt, class CoordsAt>
void group_sorted(std::size_t m, Same same, IndexAt index_at, CoordsAt coords_at,
                  std::vector<std::int64_t>& offsets, std::vector<std::int32_t>& coords,
                  std::vector<std::int32_t>& indices, std::vector<std::int32_t>& sample_voxel,
                  std::int32_t& max_occupancy) {
    const int max_threads = threads_for(m);
    std::vector<std::size_t> starts(static_cast<std::size_t>(max_threads) + 1, 0);
    indices.resize(m);
    std::int32_t max_occ = 0;
    // Carries std::bad_alloc out of the region; every thread still meets every barrier, and after
    // a failure (seen by all after the next barrier) the remaining stretches do nothing.
    InterruptPoll failure;
#pragma omp parallel num_threads(max_threads)
    {
        const int threads = omp_get_num_threads(), t = omp_get_thread_num();
        const std::size_t b = chunk_begin(m, t, threads), e = chunk_begin(m, t + 1, threads);
        // Where this thread's chunk starts new voxels: kept, so that the second pass visits
        // only those rather than every sample.
        std::vector<std::size_t> firsts;
        failure.guard([&] {
            firsts.reserve((e - b) / 4 + 16);
            for (std::size_t j = b; j < e; ++j) {
                if (j == 0 || !same(j)) firsts.push_back(j);
                indices[j] = index_at(j);
            }
        });
        starts[static_cast<std::size_t>(t) + 1] = firsts.size();
#pragma omp barrier
#pragma omp single
        for (int u = 0; u < threads; ++u) starts[u + 1] += starts[u];
        // The two outputs are zero-filled by two threads at once.
#pragma omp single nowait
        failure.guard([&] {
            offsets.resize(starts[threads] + 1);
            offsets[starts[threads]] = static_cast<std::int64_t>(m);
        });
#pragma omp single nowait
        failure.guard([&] { coords.resize(3 * starts[threads]); });
#pragma omp barrier
        if (!failure.stopped()) {
            std::size_t v = starts[t];
            for (const std::size_t j : firsts) {
                offsets[v] = static_cast<std::int64_t>(j);
                coords_at(j, &coords[3 * v]);
                ++v;
            }
        }
#pragma omp barrier
        const std::int64_t voxels = failure.stopped() ? 0 : static_cast<std::int64_t>(offsets.size()) - 1;
#pragma omp for schedule(static) reduction(max : max_occ)
        for (std::int64_t u = 0; u < voxels; ++u) {
            max_occ = std::max(max_occ, static_cast<std::int32_t>(offsets[u + 1] - offsets[u]));
            for (std::int64_t j = offsets[u]; j < offsets[u + 1]; ++j)
                sample_voxel[indices[j]] = static_cast<std::int32_t>(u);
        }
    }
    failure.throw_if_stopped();
    max_occupancy = max_occ;
}

}  // namespace

SparseVoxelGrid::SparseVoxelGrid(const float* positions, std::size_t n, double voxel_size,
                                 InvalidPolicy on_invalid, const std::uint8_t* keep,
                                 const char* name)
    : voxel_size_(voxel_size) {
    if (!(std::isfinite(voxel_size) && voxel_size > 0.0)) {
        std::ostringstream os;
        os << "voxel_size: expected a finite value > 0, got " << voxel_size;
        throw std::invalid_argument(os.str());
    }
    if (n > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
        throw std::invalid_argument(std::string(name) + ": " + std::to_string(n) +
                                    " samples; SparseVoxelGrid indexes at most 2^31 - 1");
    if (n > 0 && !positions) throw std::invalid_argument(std::string(name) + ": null array");

    // Pass 1: the invalid samples and the bounding box of the valid positions. round(p / v) is
    // monotone in p, so the keys' box is the box of the positions' keys, and no key is stored.
    const bool may_drop = keep != nullptr || on_invalid == InvalidPolicy::Drop;
    std::unique_ptr<std::uint8_t[]> valid(may_drop ? new std::uint8_t[n] : nullptr);
    const int max_threads = threads_for(n);
    std::vector<BadCoordinate> bad(static_cast<std::size_t>(max_threads));
    std::vector<PointBox> boxes(static_cast<std::size_t>(max_threads));
    std::vector<std::size_t> valid_count(static_cast<std::size_t>(max_threads) + 1, 0);
    int used_threads = 1;
#pragma omp parallel num_threads(max_threads)
    {
        const int threads = omp_get_num_threads(), t = omp_get_thread_num();
#pragma omp single
        used_threads = threads;
        const std::size_t b = chunk_begin(n, t, threads), e = chunk_begin(n, t + 1, threads);
        PointBox box;
        BadCoordinate first_bad;
        std::size_t count = 0;
        for (std::size_t i = b; i < e; ++i) {
            bool ok = keep == nullptr || keep[i] != 0;
            const float* p = positions + 3 * i;
            if (ok && !(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]))) {
                if (on_invalid == InvalidPolicy::Raise) {
                    const int axis = std::isfinite(p[0]) ? (std::isfinite(p[1]) ? 2 : 1) : 0;
                    first_bad = {i, axis, p[axis], false};
                    break;
                }
                ok = false;
            }
            if (ok) {
                for (int a = 0; a < 3; ++a) {
                    box.lo[a] = std::min(box.lo[a], p[a]);
                    box.hi[a] = std::max(box.hi[a], p[a]);
                }
                ++count;
            }
            if (may_drop) valid[i] = ok;
        }
        bad[t] = first_bad;
        boxes[t] = box;
        valid_count[static_cast<std::size_t>(t) + 1] = count;
    }
    const BadCoordinate* first = &bad[0];
    for (int t = 1; t < used_threads; ++t)
        if (bad[t].index < first->index) first = &bad[t];
    if (first->index != std::numeric_limits<std::size_t>::max())
        throw_bad_coordinate(*first, voxel_size, name);

    PointBox box;
    for (int t = 0; t < used_threads; ++t) {
        for (int a = 0; a < 3; ++a) {
            box.lo[a] = std::min(box.lo[a], boxes[t].lo[a]);
            box.hi[a] = std::max(box.hi[a], boxes[t].hi[a]);
        }
        valid_count[t + 1] += valid_count[t];
    }
    const std::size_t m = valid_count[used_threads];
    reserve_huge(sample_voxel_, n);
    sample_voxel_.assign(n, -1);
    reserve_huge(sample_indices_, m);
    if (m == 0) return;

    std::int32_t key_lo[3], key_hi[3];
    for (int a = 0; a < 3; ++a) {
        const double lo = static_cast<double>(box.lo[a]) / voxel_size;
        const double hi = static_cast<double>(box.hi[a]) / voxel_size;
        if (!(lo > kKeyLow && hi < kKeyHigh)) {
            // Some key overflows: name the first sample whose key does.
            for (std::size_t i = 0; i < n; ++i) {
                if (valid && !valid[i]) continue;
                for (int b = 0; b < 3; ++b) {
                    const double x = static_cast<double>(positions[3 * i + b]) / voxel_size;
                    if (!(x > kKeyLow && x < kKeyHigh))
                        throw_bad_coordinate({i, b, positions[3 * i + b], true}, voxel_size, name);
                }
            }
        }
        key_lo[a] = round_key(lo);
        key_hi[a] = round_key(hi);
    }

    int axis_bits[3];
    for (int a = 0; a < 3; ++a)
        axis_bits[a] = bit_width(static_cast<std::uint64_t>(static_cast<std::int64_t>(key_hi[a]) -
                                                            static_cast<std::int64_t>(key_lo[a])));
    const int index_bits = bit_width(n - 1);
    const int key_bits = axis_bits[0] + axis_bits[1] + axis_bits[2];

    // The key of valid sample i, relative to key_lo (fits the axis' bits).
    const double inv_voxel = 1.0 / voxel_size;
    const auto relative_key = [&](std::size_t i, int a) {
        const std::int32_t k = key_of(static_cast<double>(positions[3 * i + a]), voxel_size, inv_voxel);
        return static_cast<std::uint64_t>(static_cast<std::int64_t>(k) - key_lo[a]);
    };

    if (key_bits + index_bits <= 64) {
        // Pack (relative key, index) so that one integer sort orders voxels lexicographically.
        const int shift_z = index_bits, shift_y = shift_z + axis_bits[2],
                  shift_x = shift_y + axis_bits[1];
        std::unique_ptr<std::uint64_t[]> buf0(new std::uint64_t[m]), buf1(new std::uint64_t[m]);
        advise_huge_pages(buf0.get(), m * sizeof(std::uint64_t));
        advise_huge_pages(buf1.get(), m * sizeof(std::uint64_t));
        std::uint64_t* packed = buf0.get();
        // The keys lie in the box of pass 1 unless the positions changed since (another thread
        // writing to the caller's array during the call): then a key may spill past its field.
        // Masking keeps the radix sort's contract (no bits from hi_bit on) and the index bits
        // exact, so such a race gives wrong voxels, never an out-of-bounds access. Each chunk is
        // masked by the thread that packed it, while it is in cache.
        const std::uint64_t used_bits = low_mask(index_bits + key_bits);
        // Pass 1's chunks, so that valid_count gives each chunk's first output slot.
#pragma omp parallel for schedule(static) num_threads(used_threads)
        for (int c = 0; c < used_threads; ++c) {
            const std::size_t b = chunk_begin(n, c, used_threads), e = chunk_begin(n, c + 1, used_threads);
            std::size_t j = valid_count[c];
            const auto exact = [&](std::size_t i) {
                return shift_left(relative_key(i, 0), shift_x) | shift_left(relative_key(i, 1), shift_y) |
                       shift_left(relative_key(i, 2), shift_z) | static_cast<std::uint64_t>(i);
            };
            if (valid) {
                for (std::size_t i = b; i < e; ++i)
                    if (valid[i]) packed[j++] = exact(i) & used_bits;
                continue;
            }
            // Every sample valid: the vectorised packing, by pieces; a piece with a coordinate
            // near a rounding half (a few in a million) is redone exactly.
            const int shifts[3] = {axis_bits[0] ? shift_x : 0, axis_bits[1] ? shift_y : 0, axis_bits[2] ? shift_z : 0};
            constexpr std::size_t kPiece = 4096;
            for (std::size_t pb = b; pb < e; pb += kPiece) {
                const std::size_t pe = std::min(e, pb + kPiece);
                std::uint64_t* out = packed + j + (pb - b);
                if (pack_keys(positions, pb, pe, inv_voxel, key_lo, shifts, out))
                    for (std::size_t i = pb; i < pe; ++i) out[i - pb] = exact(i);
                for (std::size_t i = 0; i < pe - pb; ++i) out[i] &= used_bits;
            }
        }
        const std::uint64_t* sorted = radix_sort(packed, buf1.get(), m, index_bits, index_bits + key_bits);
        const std::uint64_t index_mask = low_mask(index_bits);
        const std::uint64_t mz = low_mask(axis_bits[2]), my = low_mask(axis_bits[1]),
                            mx = low_mask(axis_bits[0]);
        group_sorted(
            m, [&](std::size_t j) { return (sorted[j] >> index_bits) == (sorted[j - 1] >> index_bits); },
            [&](std::size_t j) { return static_cast<std::int32_t>(sorted[j] & index_mask); },
            [&](std::size_t j, std::int32_t* out) {
                const std::uint64_t key = sorted[j];
                out[0] = static_cast<std::int32_t>(key_lo[0] + static_cast<std::int64_t>((key >> shift_x) & mx));
                out[1] = static_cast<std::int32_t>(key_lo[1] + static_cast<std::int64_t>((key >> shift_y) & my));
                out[2] = static_cast<std::int32_t>(key_lo[2] + static_cast<std::int64_t>((key >> shift_z) & mz));
            },
            voxel_offsets_, voxel_coords_, sample_indices_, sample_voxel_, max_occupancy_);
        return;
    }

    // Key range too wide to pack with the index: comparison sort on (kx, ky, kz, index), a
    // strict total order, so the parallel sort's result is unique.
    struct Entry {
        std::int32_t k[3];
        std::int32_t index;
    };
    std::vector<Entry> entries(m);
    {
        std::size_t j = 0;
        for (std::size_t i = 0; i < n; ++i) {
            if (valid && !valid[i]) continue;
            Entry& e = entries[j++];
            for (int a = 0; a < 3; ++a) e.k[a] = round_key(static_cast<double>(positions[3 * i + a]) / voxel_size);
            e.index = static_cast<std::int32_t>(i);
        }
    }
    __gnu_parallel::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
        if (a.k[0] != b.k[0]) return a.k[0] < b.k[0];
        if (a.k[1] != b.k[1]) return a.k[1] < b.k[1];
        if (a.k[2] != b.k[2]) return a.k[2] < b.k[2];
        return a.index < b.index;
    });
    group_sorted(
        m,
        [&](std::size_t j) {
            return std::memcmp(entries[j].k, entries[j - 1].k, sizeof(entries[j].k)) == 0;
        },
        [&](std::size_t j) { return entries[j].index; },
        [&](std::size_t j, std::int32_t* out) { std::copy_n(entries[j].k, 3, out); },
        voxel_offsets_, voxel_coords_, sample_indices_, sample_voxel_, max_occupancy_);
}

std::vector<std::int32_t> SparseVoxelGrid::occupancy() const {
    std::vector<std::int32_t> occ(num_voxels());
    for (std::size_t v = 0; v < occ.size(); ++v) occ[v] = occupancy(v);
    return occ;
}

}  // namespace avsplat
