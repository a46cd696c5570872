// simplify's Merge method: rounds of greedy pairwise merging by moment matching (the cost and
// the merge are in moment_merge.h; the rounds are described in avsplat/reduce/simplify.h).
#include "common/interrupt_poll.h"
#include "common/kdtree.h"
#include "common/parallel.h"
#include "reduce/moment_merge.h"
#include "reduce/simplify_methods.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace avsplat::reduce_detail {

namespace {

/// Candidate partners per Gaussian and round (its nearest means, itself excluded); splat-transform
/// uses 16 too. 8 was 1.4-1.6x faster but up to 0.9 dB further from the unreduced renders at 1/8
/// and 1/16 (reduction report scenes).
constexpr std::size_t kNeighbours = 16;
/// At most this share of the Gaussians goes in one round: a round that must pair up nearly
/// everything (a half) ends with its worst pairs; smaller rounds recompute neighbours and costs
/// in between (measured in the reduction report: +1.5 dB at a ratio of 1/2 over halving).
constexpr double kRoundShare = 0.4;

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

std::vector<std::uint32_t> round_pairs(const GaussianCloud& in, const std::vector<MergeInput>& g, std::size_t needed) {
    const std::size_t n = in.size();
    const std::size_t k3 = std::size_t(in.sh_coeffs()) * 3;
    const std::size_t k = std::min(kNeighbours, n - 1);
    const std::int64_t sn = std::int64_t(n);

    // The k nearest others of every mean. Queries go in the tree's leaf order, so consecutive
    // ones visit the same leaves (the lists do not depend on the order).
    std::vector<std::uint32_t> nb(n * k, kNone);
    const detail::KdTree tree(in.means.data(), n, "simplify");
    const std::vector<std::uint32_t>& order = tree.leaf_order();
    InterruptPoll poll;
#pragma omp parallel num_threads(threads_for(n))
    {
        std::vector<std::uint32_t> idx;
        std::vector<double> d2;
        poll.guard([&] {
            idx.resize(k + 1);
            d2.resize(k + 1);
        });
#pragma omp for schedule(static)
        for (std::int64_t si = 0; si < sn; ++si) {
            if (poll.stop(si)) continue;
            const std::size_t i = order[std::size_t(si)];
            const std::size_t found = tree.knn(&in.means[3 * i], k + 1, idx.data(), d2.data());
            // Coincident points come back in the tree's order, which need not put i first:
            // drop i wherever it is and keep the k nearest others.
            std::size_t o = 0;
            for (std::size_t t = 0; t < found && o < k; ++t)
                if (idx[t] != i) nb[i * k + o++] = idx[t];
        }
    }
    poll.throw_if_stopped();

    // Each unordered pair once: from i's list when i < j, or when i is not in j's list.
    std::vector<Edge> slots(n * k, Edge{HUGE_VAL, kNone, kNone});
#pragma omp parallel for schedule(static) num_threads(threads_for(n))
    for (std::int64_t si = 0; si < sn; ++si) {
        if (poll.stop(si)) continue;
        const std::uint32_t i = std::uint32_t(si);
        for (std::size_t t = 0; t < k; ++t) {
            const std::uint32_t j = nb[i * k + t];
            if (j == kNone) continue;
            if (j < i) {
                const std::uint32_t* lj = &nb[std::size_t(j) * k];
                if (std::find(lj, lj + k, i) != lj + k) continue;
            }
            const std::uint32_t a = std::min(i, j), b = std::max(i, j);
            slots[i * k + t] = Edge{merge_cost(g[a], g[b], &in.sh[k3 * a], &in.sh[k3 * b], k3), a, b};
        }
    }
    poll.throw_if_stopped();
    slots.erase(std::remove_if(slots.begin(), slots.end(), [](const Edge& e) { return e.a == kNone; }),
                slots.end());

    // Greedy matching in increasing (cost, a, b), a total order, so the matching is unique. The
    // scan stops once `needed` pairs are taken, long before the end of the list: sort a prefix
    // of the cheapest (nth_element, then sort), and the next, twice as long, only when the
    // prefix runs out. The order the scan sees is that of a full sort.
    std::vector<std::uint32_t> partner(n, kNone);
    std::size_t merged = 0, done = 0;
    std::size_t chunk = std::max<std::size_t>(4 * needed, 4096);
    while (merged < needed && done < slots.size()) {
        const std::size_t end = std::min(slots.size(), done + chunk);
        if (end < slots.size())
            std::nth_element(slots.begin() + std::ptrdiff_t(done), slots.begin() + std::ptrdiff_t(end), slots.end());
        std::sort(slots.begin() + std::ptrdiff_t(done), slots.begin() + std::ptrdiff_t(end));
        for (; done < end && merged < needed; ++done) {
            const Edge& e = slots[done];
            if (partner[e.a] != kNone || partner[e.b] != kNone) continue;
            partner[e.a] = e.b;
            partner[e.b] = e.a;
            ++merged;
        }
        chunk *= 2;
    }
    return partner;
}

namespace {

/// One round: merges disjoint pairs, cheapest first, until `needed` Gaussians are gone (or no
/// free pair is left). Replaces `in` and `g` by the new cloud and its MergeInput rows; rows keep
/// the order of the smaller index of each pair (deterministic, as every step is a function of the
/// input rows).
void merge_round(GaussianCloud& in, std::vector<MergeInput>& g, std::size_t needed) {
    const std::size_t n = in.size();
    const std::size_t k3 = std::size_t(in.sh_coeffs()) * 3;
    const std::int64_t sn = std::int64_t(n);
    const std::vector<std::uint32_t> partner = round_pairs(in, g, needed);

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

GaussianCloud merge_to_count(const GaussianCloud& cloud, std::size_t target, int& rounds) {
    GaussianCloud current = cloud;
    // Rows left alone keep their MergeInput from round to round; merged rows get theirs anew.
    std::vector<MergeInput> g(current.size());
    const std::int64_t sn = std::int64_t(current.size());
#pragma omp parallel for schedule(static) num_threads(threads_for(current.size()))
    for (std::int64_t si = 0; si < sn; ++si) g[std::size_t(si)] = MergeInput::of(current, std::size_t(si));
    rounds = 0;
    while (current.size() > target) {
        const std::size_t n = current.size();
        const std::size_t needed =
            std::min(n - target, std::max<std::size_t>(1, std::size_t(kRoundShare * double(n))));
        // Every Gaussian has a neighbour (n >= 2), so the cheapest edge is always taken.
        merge_round(current, g, needed);
        ++rounds;
    }
    return current;
}

}  // namespace avsplat::reduce_detail
