// simplify's Merge method: rounds of greedy pairwise merging by moment matching (the cost and
// the merge are in moment_merge.h; the rounds are described in avsplat/reduce/simplify.h).
#include "avsplat/core/morton_order.h"
#include "core/interrupt_poll.h"
#include "core/progress_report.h"
#include "common/all_knn.h"
#include "common/parallel.h"
#include "common/parallel_compact.h"
#include "common/radix_sort.h"
#include "reduce/merge_cost_bound.h"
#include "reduce/moment_merge.h"
#include "reduce/simplify_methods.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

namespace avsplat::reduce_detail {

namespace {

/// Candidate partners per Gaussian (its nearest means, itself excluded) in the first round and in
/// the later ones (splat-transform uses 16). The first round pairs up the input's nearest
/// Gaussians; the later ones merge merged Gaussians, larger and more irregular, whose cheapest
/// partner lies further down the list. On the reduction report's scenes (PSNR / SSIM against the
/// unreduced renders, time at 2 threads on Zen 1), 8 then 12 against 16 throughout: 1.44x faster
/// at 1/2 and 1.36x at 1/16; the embedded (fused) scene within 0.05 dB in PSNR and up to 0.006
/// closer in SSIM at 1/8 and 1/16; the trained-like ones about 1 dB further at 1/2 (still
/// 1.4-3 dB ahead of splat-transform), 0.1-0.5 dB further at 1/4 and 1/8 and level at 1/16.
/// 8 throughout (1.6x) lost up to 1.1 dB at 1/8; 12 throughout and 8 then 16 were slower for no
/// better results (README, reduction).
constexpr std::size_t kFirstNeighbours = 8;
constexpr std::size_t kNeighbours = 12;
/// At most this share of the Gaussians goes in one round: a round that must pair up nearly
/// everything (a half) ends with its worst pairs; smaller rounds recompute neighbours and costs
/// in between (measured in the reduction report: +1.5 dB at a ratio of 1/2 over halving).
constexpr double kRoundShare = 0.4;

/// A candidate pair and a lower bound of its cost (>= 0, finite, so its bits order as it does).
struct Candidate {
    float bound;
    std::uint32_t a, b;
    std::uint64_t key() const {
        std::uint32_t bits;
        std::memcpy(&bits, &bound, sizeof bits);
        return bits;
    }
    /// The next float below f > 0 (finite): std::nextafter(f, 0.0f) without the call into libm.
    static float below(float f) {
        std::uint32_t bits;
        std::memcpy(&bits, &f, sizeof bits);
        --bits;
        std::memcpy(&f, &bits, sizeof f);
        return f;
    }
    /// Low key bits that coarse() clears: the sort reads the other 24 (one radix pass fewer).
    static constexpr int kDropBits = 8;
    /// f with its low kDropBits mantissa bits cleared: rounded toward 0, so still a lower bound
    /// (2^-15 looser at most, relatively, which prices no more pairs measurably).
    static float coarse(float f) {
        std::uint32_t bits;
        std::memcpy(&bits, &f, sizeof bits);
        bits &= ~((std::uint32_t(1) << kDropBits) - 1);
        std::memcpy(&f, &bits, sizeof f);
        return f;
    }
};

struct Edge {
    double cost;
    std::uint32_t a, b;  // a < b
    bool operator<(const Edge& o) const {
        if (cost != o.cost) return cost < o.cost;
        if (a != o.a) return a < o.a;
        return b < o.b;
    }
};

}  // namespace

std::vector<std::uint32_t> round_pairs(const GaussianCloud& in, const std::vector<MergeInput>& g, std::size_t needed,
                                       std::size_t neighbours) {
    const std::size_t n = in.size();
    const std::size_t k3 = std::size_t(in.sh_coeffs()) * 3;
    const std::size_t k = std::min(neighbours, n - 1);
    const std::int64_t sn = std::int64_t(n);

    // The k nearest others of every mean, a leaf of the tree at a time (exact; ties by index).
    std::vector<std::uint32_t> nb(n * k, kNone);
    const detail::AllKnnTree tree(in.means.data(), n, "simplify");
    const std::int64_t leaves = std::int64_t(tree.leaf_count());
    InterruptPoll poll;
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads_for(n))
    for (std::int64_t l = 0; l < leaves; ++l) {
        if (poll.stop(l)) continue;
        poll.guard([&] { tree.all_knn_leaf(std::size_t(l), k, nb.data()); });
    }
    poll.throw_if_stopped();

    // Each unordered pair once: from i's list when i < j, or when i is not in j's list. Each gets
    // the lower bound of its cost (in float, rounded down: still a lower bound); merge_cost
    // itself only when the greedy scan reaches it.
    // (The arrays of candidates are not zeroed: every slot is written below, and then only the
    // kept ones are read; zeroing and compacting them on one thread was 5 % of the wall time.)
    std::unique_ptr<Candidate[]> slots(new Candidate[n * k]);
#pragma omp parallel for schedule(static) num_threads(threads_for(n))
    for (std::int64_t si = 0; si < sn; ++si) {
        if (poll.stop(si)) continue;  // (then throw_if_stopped throws before a slot is read)
        const std::uint32_t i = std::uint32_t(si);
        for (std::size_t t = 0; t < k; ++t) {
            const std::uint32_t j = nb[i * k + t];
            slots[i * k + t] = Candidate{0.0f, kNone, kNone};
            if (j == kNone) continue;
            if (j < i) {
                const std::uint32_t* lj = &nb[std::size_t(j) * k];
                bool mutual = false;  // i in j's list (a loop without exits: vectorised)
                for (std::size_t u = 0; u < k; ++u) mutual |= lj[u] == i;
                if (mutual) continue;
            }
            const std::uint32_t a = std::min(i, j), b = std::max(i, j);
            const double lb = merge_cost_lower_bound(g[a], g[b], &in.sh[k3 * a], &in.sh[k3 * b], k3);
            float f = lb < double(std::numeric_limits<float>::max()) ? float(lb) : std::numeric_limits<float>::max();
            if (double(f) > lb) f = Candidate::below(f);
            slots[i * k + t] = Candidate{Candidate::coarse(f), a, b};
        }
    }
    poll.throw_if_stopped();
    std::unique_ptr<Candidate[]> packed(new Candidate[n * k]);
    const std::size_t count =
        parallel_compact(slots.get(), n * k, packed.get(), [](const Candidate& e) { return e.a != kNone; });
    // In increasing bound (the order among equal bounds does not matter, below).
    const Candidate* sorted = radix_sort(packed.get(), slots.get(), count, Candidate::kDropBits, 32,
                                         [](const Candidate& e) { return e.key(); });

    // Greedy matching in increasing (cost, a, b), a total order, so the matching is unique. The
    // candidates come in increasing lower bound. A candidate with an end already taken is dropped
    // unpriced (the pair that took the end costs less than its bound); the others get their cost
    // and wait in a heap, whose top is taken (when both ends are still free) once it costs less
    // than the next candidate's bound: every pair not yet priced costs at least that. So the
    // pairs taken are those of a full sort by cost, and the scan stops once `needed` are taken.
    // The costs are computed ahead, a block of candidates at a time and in parallel, for those
    // whose ends are free when the block starts (a superset of those the scan prices in it).
    std::vector<std::uint32_t> partner(n, kNone);
    // A cost takes about as long as 30 steps of the library's simple loops: a block of pricing
    // goes parallel from kParallelMin / kCostWeight candidates on (threads_for counts items; with
    // the plain count, the blocks of 8k-20k candidates ran on one thread).
    constexpr std::size_t kCostWeight = 32;
    std::vector<Edge> heap;
    auto later = [](const Edge& x, const Edge& y) { return y < x; };
    std::size_t merged = 0, done = 0;
    const std::size_t block = std::max<std::size_t>(8192, count / 64);
    std::vector<double> cost(std::min(block, count));
    std::size_t block_begin = 0, block_end = 0;
    while (merged < needed) {
        const bool more = done < count;
        if (!heap.empty() && (!more || heap.front().cost < double(sorted[done].bound))) {
            std::pop_heap(heap.begin(), heap.end(), later);
            const Edge e = heap.back();
            heap.pop_back();
            if (partner[e.a] != kNone || partner[e.b] != kNone) continue;
            partner[e.a] = e.b;
            partner[e.b] = e.a;
            ++merged;
            continue;
        }
        if (!more) break;
        if (done == block_end) {
            block_begin = done;
            block_end = std::min(count, done + block);
            const std::int64_t bb = std::int64_t(block_begin), be = std::int64_t(block_end);
#pragma omp parallel for schedule(static) num_threads(threads_for(kCostWeight * std::size_t(be - bb)))
            for (std::int64_t p = bb; p < be; ++p) {
                if (poll.stop(p)) continue;
                const Candidate& c = sorted[p];
                if (partner[c.a] == kNone && partner[c.b] == kNone)
                    cost[std::size_t(p - bb)] = merge_cost(g[c.a], g[c.b], &in.sh[k3 * c.a], &in.sh[k3 * c.b], k3);
            }
            poll.throw_if_stopped();
        }
        const Candidate& c = sorted[done];
        const double price = cost[done - block_begin];
        ++done;
        if (partner[c.a] != kNone || partner[c.b] != kNone) continue;
        heap.push_back(Edge{price, c.a, c.b});
        std::push_heap(heap.begin(), heap.end(), later);
    }
    return partner;
}

namespace {

/// One round: merges disjoint pairs, cheapest first, until `needed` Gaussians are gone (or no
/// free pair is left). Replaces `in` and `g` by the new cloud and its MergeInput rows; rows keep
/// the order of the smaller index of each pair (deterministic, as every step is a function of the
/// input rows).
void merge_round(GaussianCloud& in, std::vector<MergeInput>& g, std::size_t needed, std::size_t neighbours) {
    const std::size_t n = in.size();
    const std::size_t k3 = std::size_t(in.sh_coeffs()) * 3;
    const std::int64_t sn = std::int64_t(n);
    const std::vector<std::uint32_t> partner = round_pairs(in, g, needed, neighbours);

    // Row of each output: free Gaussians and the smaller index of each pair, in input order.
    std::vector<std::uint32_t> row(n, kNone);
    std::size_t m = 0;
    for (std::size_t i = 0; i < n; ++i)
        if (partner[i] == kNone || partner[i] > i) row[i] = std::uint32_t(m++);
    GaussianCloud out(m, in.sh_degree);
    if (in.has_confidence()) out.confidence.resize(m);
    for (const auto& e : in.extras) out.extras.push_back({e.name, std::vector<float>(m)});
    std::vector<MergeInput> next(m);
    InterruptPoll poll;
#pragma omp parallel for schedule(static) num_threads(threads_for(n))
    for (std::int64_t si = 0; si < sn; ++si) {
        if (poll.stop(si)) continue;
        const std::size_t i = std::size_t(si);
        if (row[i] == kNone) continue;
        const std::size_t o = row[i];
        if (partner[i] == kNone) {
            std::copy_n(&in.means[3 * i], 3, &out.means[3 * o]);
            std::copy_n(&in.scales[3 * i], 3, &out.scales[3 * o]);
            std::copy_n(&in.rotations[4 * i], 4, &out.rotations[4 * o]);
            out.opacities[o] = in.opacities[i];
            std::copy_n(&in.sh[k3 * i], k3, &out.sh[k3 * o]);
            if (in.has_confidence()) out.confidence[o] = in.confidence[i];
            for (std::size_t e = 0; e < in.extras.size(); ++e) out.extras[e].values[o] = in.extras[e].values[i];
            next[o] = g[i];
        } else {
            const std::size_t j = partner[i];
            merge_pair(in, i, j, g[i], g[j], out, o);
            // What the next round reads of the merged row: from the float row written, as
            // MergeInput::of(out, o) would give.
            next[o] = MergeInput::of(out, o);
        }
    }
    poll.throw_if_stopped();
    in = std::move(out);
    g = std::move(next);
}

}  // namespace

GaussianCloud merge_to_count(const GaussianCloud& cloud, const std::vector<std::size_t>& order, std::size_t target,
                             int& rounds) {
    // The rounds work in Morton order of the means (morton_order over the canonical order:
    // ties in that order, so still deterministic): neighbours in space are then near in memory
    // (2-4 % less time than the canonical order, which is by x first). One copy of the cloud.
    GaussianCloud current = select(cloud, morton_order(cloud, order));
    // Rows left alone keep their MergeInput from round to round; merged rows get theirs anew.
    std::vector<MergeInput> g(current.size());
    const std::int64_t sn = std::int64_t(current.size());
#pragma omp parallel for schedule(static) num_threads(threads_for(current.size()))
    for (std::int64_t si = 0; si < sn; ++si) g[std::size_t(si)] = MergeInput::of(current, std::size_t(si));
    rounds = 0;
    ProgressReport report(current.size() > target ? current.size() - target : 0);  // Gaussians removed
    while (current.size() > target) {
        const std::size_t n = current.size();
        const std::size_t needed =
            std::min(n - target, std::max<std::size_t>(1, std::size_t(kRoundShare * double(n))));
        // Every Gaussian has a neighbour (n >= 2), so the cheapest edge is always taken.
        merge_round(current, g, needed, rounds == 0 ? kFirstNeighbours : kNeighbours);
        ++rounds;
        report.set(std::uint64_t(sn) - current.size());
    }
    report.finish();
    return current;
}

}  // namespace avsplat::reduce_detail
