// The SOG writer's SH palette (codebook.h): k-means of the SH-rest vectors, with an exhaustive
// nearest-centre search (Hamerly's bounds) or, for large problems, a grouped one.
#include "io/sog/codebook.h"

#include "common/cpu_dispatch.h"
#include "core/interrupt_poll.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace avsplat::sog {

namespace {

// splitmix64: a small generator whose sequence is fixed by its seed on every platform (the
// standard distributions are not).
struct SplitMix {
    std::uint64_t state;
    std::uint64_t next() {
        std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    // Uniform in [0, n) (the bias of a 64-bit modulo is below 2^-40 for n < 2^24).
    std::size_t below(std::size_t n) { return static_cast<std::size_t>(next() % n); }
};

// Points per block of the nearest-centre search: their coordinates are stored transposed, so
// that the inner loop runs over 64 points at once in vector registers.
constexpr std::size_t kBlock = 64;

// Squared norm of one row (summed in double).
double squared_norm(const float* x, int dims) {
    double s = 0;
    for (int d = 0; d < dims; ++d) s += double(x[d]) * x[d];
    return s;
}

// A point whose squared distance to a centre is at most this share of its squared norm lies on
// that centre within the float rounding of the score (cn - 2 x.c cancels against ||x||^2): it
// takes no other centre (see nearest_two).
constexpr double kOnCentre = 1e-6;

// The nearest and second nearest centre of each point of a block, by ||c||^2 - 2 x.c (the
// point's own norm `xn` left out: d^2 = xn + d1), and each point's `floor`: the score at which it
// lies on a centre (-(1 - kOnCentre) xn; +inf for the padding lanes, which take nothing). start()
// before the first nearest_two.
struct Nearest {
    std::uint32_t best[kBlock];
    float d1[kBlock], d2[kBlock], floor[kBlock];
    double xn[kBlock];
    void start(const float* points, const std::uint32_t* idx, std::size_t count, int dims) {
        for (std::size_t p = 0; p < kBlock; ++p) {
            best[p] = 0;
            d1[p] = d2[p] = std::numeric_limits<float>::infinity();
            xn[p] = p < count ? squared_norm(points + std::size_t(idx[p]) * dims, dims) : 0.0;
            floor[p] = p < count ? static_cast<float>(-(1.0 - kOnCentre) * xn[p])
                                 : std::numeric_limits<float>::infinity();
        }
    }
};

// Rows 0 .. n of `key` (each < buckets) by key, in row order within a key: begin[b] .. begin[b + 1]
// are the positions of bucket b in `order` (a counting sort).
void bucket_sort(const std::vector<std::uint32_t>& key, std::size_t buckets, std::vector<std::uint32_t>& begin,
                 std::vector<std::uint32_t>& order) {
    begin.assign(buckets + 1, 0);
    for (const std::uint32_t b : key) ++begin[b + 1];
    for (std::size_t b = 0; b < buckets; ++b) begin[b + 1] += begin[b];
    order.resize(key.size());
    std::vector<std::uint32_t> next(begin.begin(), begin.end() - 1);
    for (std::size_t r = 0; r < key.size(); ++r) order[next[key[r]]++] = std::uint32_t(r);
}

// acc[p] = x_p . c for the kBlock points of `xt` (dims x kBlock, transposed) and one centre `c`,
// summed over d in order (inlined into each caller's clone, so every caller sums alike).
__attribute__((always_inline)) inline void block_dot(const float* xt, const float* c, int dims, float* acc) {
    for (std::size_t p = 0; p < kBlock; ++p) acc[p] = 0.f;
    for (int d = 0; d < dims; ++d) {
        const float v = c[d];
        const float* row = xt + std::size_t(d) * kBlock;
        for (std::size_t p = 0; p < kBlock; ++p) acc[p] += row[p] * v;
    }
}

// Updates `r` with the k centres at `centres` (norms `cnorm`) for the kBlock points of `xt`
// (dims x kBlock, transposed); centre c is reported as offset + c. A centre replaces the best
// only when strictly nearer (ties keep the earlier), and none replaces a best at or below the
// point's floor (the point lies on it); its second distance is then -inf (a lower bound of 0 for
// Hamerly's test). The scan stops once every point of the block lies on a centre: equal vectors
// (higher SH bands all 0, say) cost one centre, not k. Each point's result depends on its own
// coordinates only, not on the other points of the block, so the grouping into blocks (and
// threads) cannot change it.
AVSPLAT_CLONES_V3
void nearest_two(const float* xt, const float* centres, const float* cnorm, std::size_t k, int dims,
                 std::uint32_t offset, Nearest& r) {
    float b1[kBlock], b2[kBlock];
    std::uint32_t bi[kBlock];
    for (std::size_t p = 0; p < kBlock; ++p) {
        b1[p] = r.d1[p];
        b2[p] = r.d2[p];
        bi[p] = r.best[p];
    }
    for (std::size_t c = 0; c < k; ++c) {
        if (c % 8 == 0) {
            bool open = false;
            for (std::size_t p = 0; p < kBlock; ++p) open |= b1[p] > r.floor[p];
            if (!open) break;
        }
        float acc[kBlock];
        block_dot(xt, centres + c * dims, dims, acc);
        const float cn = cnorm[c];
        const auto ci = static_cast<std::uint32_t>(offset + c);
        for (std::size_t p = 0; p < kBlock; ++p) {
            const float s = cn - 2.f * acc[p];
            const bool lt = s < b1[p] && b1[p] > r.floor[p];
            b2[p] = lt ? b1[p] : std::min(b2[p], s);
            b1[p] = lt ? s : b1[p];
            bi[p] = lt ? ci : bi[p];
        }
    }
    for (std::size_t p = 0; p < kBlock; ++p) {
        r.best[p] = bi[p];
        r.d1[p] = b1[p];
        r.d2[p] = b1[p] <= r.floor[p] ? -std::numeric_limits<float>::infinity() : b2[p];
    }
}

// Rows idx[0 .. count) of `points` transposed into xt (dims x kBlock; the padding is 0).
void transpose(const float* points, const std::uint32_t* idx, std::size_t count, int dims, float* xt) {
    std::fill(xt, xt + std::size_t(dims) * kBlock, 0.f);
    for (std::size_t p = 0; p < count; ++p)
        for (int d = 0; d < dims; ++d) xt[std::size_t(d) * kBlock + p] = points[std::size_t(idx[p]) * dims + d];
}

// Squared norms of k rows (summed in double).
std::vector<float> norms(const float* rows, std::size_t k, int dims) {
    std::vector<float> out(k);
    for (std::size_t c = 0; c < k; ++c) {
        double s = 0;
        for (int d = 0; d < dims; ++d) s += double(rows[c * dims + d]) * rows[c * dims + d];
        out[c] = static_cast<float>(s);
    }
    return out;
}

float distance(const float* a, const float* b, int dims) {
    double s = 0;
    for (int d = 0; d < dims; ++d) s += (double(a[d]) - b[d]) * (double(a[d]) - b[d]);
    return static_cast<float>(std::sqrt(s));
}

// The nearest two of the k `centres` for the points `which` (all n when empty), a block of kBlock
// at a time in parallel: done(idx, count, r) receives each block's point indices and result.
template <class Done>
void nearest_blocks(const float* points, std::size_t n, int dims, const float* centres, std::size_t k,
                    const std::vector<std::uint32_t>& which, const Done& done) {
    const std::vector<float> cnorm = norms(centres, k, dims);
    const std::size_t m = which.empty() ? n : which.size();
    const auto blocks = static_cast<std::ptrdiff_t>((m + kBlock - 1) / kBlock);
    InterruptPoll poll;
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t b = 0; b < blocks; ++b) {
        if (poll.stop()) continue;
        std::vector<float> xt(std::size_t(dims) * kBlock);
        std::uint32_t idx[kBlock];
        const std::size_t first = std::size_t(b) * kBlock, count = std::min(kBlock, m - first);
        for (std::size_t p = 0; p < count; ++p) idx[p] = which.empty() ? std::uint32_t(first + p) : which[first + p];
        transpose(points, idx, count, dims, xt.data());
        Nearest r;
        r.start(points, idx, count, dims);
        nearest_two(xt.data(), centres, cnorm.data(), k, dims, 0, r);
        done(idx, count, r);
    }
    poll.throw_if_stopped();
}

// Nearest of the k `centres` for each of the n rows of `points`: labels[i].
void nearest_all(const float* points, std::size_t n, int dims, const float* centres, std::size_t k,
                 std::vector<std::uint32_t>& labels) {
    nearest_blocks(points, n, dims, centres, k, {}, [&](const std::uint32_t* idx, std::size_t count, const Nearest& r) {
        for (std::size_t p = 0; p < count; ++p) labels[idx[p]] = r.best[p];
    });
}

// Nearest centre of the points `which` (all when empty), with Hamerly's bounds: u the distance to
// the assigned centre, l a lower bound of the distance to any other.
void search(const float* points, std::size_t n, int dims, const std::vector<float>& centres, std::size_t k,
            const std::vector<std::uint32_t>& which, std::vector<std::uint32_t>& labels,
            std::vector<float>& u, std::vector<float>& l) {
    nearest_blocks(points, n, dims, centres.data(), k, which,
                   [&](const std::uint32_t* idx, std::size_t count, const Nearest& r) {
                       for (std::size_t p = 0; p < count; ++p) {
                           const std::size_t i = idx[p];
                           labels[i] = r.best[p];
                           u[i] = std::sqrt(std::max(0.0, r.xn[p] + r.d1[p]));
                           l[i] = std::sqrt(std::max(0.0, r.xn[p] + r.d2[p]));
                       }
                   });
}

// The grouped search: the centres fall into about sqrt(k) groups (a coarse k-means of the
// centres themselves), and a point is compared with the centres of the kProbes groups whose
// centroids are nearest to it: about (1 + kProbes) sqrt(k) centres instead of k.
constexpr std::size_t kProbes = 8;

struct Groups {
    std::size_t count = 0;               // G
    std::vector<float> centroids;        // G x dims
    std::vector<std::uint32_t> begin;    // G + 1: group g holds slots [begin[g], begin[g + 1])
    std::vector<std::uint32_t> centre;   // the centre in each slot
    std::vector<float> rows, row_norms;  // the centres in slot order, and their squared norms
};

// Groups the k centres: `steps` Lloyd steps of the groups' centroids over the centres, from the
// previous call's centroids (the first call starts from evenly spaced centres), each centre in
// the group of its nearest centroid.
void regroup(const std::vector<float>& centres, std::size_t k, int dims, int steps, Groups& g) {
    const std::size_t G = g.count;
    if (g.centroids.empty()) {
        g.centroids.resize(G * dims);
        for (std::size_t j = 0; j < G; ++j)
            std::copy_n(&centres[(j * k / G) * dims], dims, &g.centroids[j * dims]);
    }
    std::vector<std::uint32_t> member(k);
    std::vector<double> sums(G * dims);
    std::vector<std::size_t> counts(G);
    for (int s = 0; s < steps; ++s) {
        nearest_all(centres.data(), k, dims, g.centroids.data(), G, member);
        std::fill(sums.begin(), sums.end(), 0.0);
        std::fill(counts.begin(), counts.end(), 0);
        for (std::size_t c = 0; c < k; ++c) {
            ++counts[member[c]];
            for (int d = 0; d < dims; ++d) sums[member[c] * dims + d] += centres[c * dims + d];
        }
        for (std::size_t j = 0; j < G; ++j)  // an empty group keeps its centroid
            if (counts[j] > 0)
                for (int d = 0; d < dims; ++d)
                    g.centroids[j * dims + d] = static_cast<float>(sums[j * dims + d] / double(counts[j]));
    }
    // Slots by group, centres in index order within a group.
    bucket_sort(member, G, g.begin, g.centre);
    g.rows.resize(k * dims);
    for (std::size_t s = 0; s < k; ++s) std::copy_n(&centres[std::size_t(g.centre[s]) * dims], dims, &g.rows[s * dims]);
    g.row_norms = norms(g.rows.data(), k, dims);
}

// The P nearest of the G centroids for each point of the block `xt` (by ||c||^2 - 2 x.c, ties
// by index), nearest first: top[p * P + t]. `score` is scratch of G x kBlock floats.
AVSPLAT_CLONES_V3
void nearest_groups(const float* xt, const float* centroids, const float* cnorm, std::size_t G, int dims,
                    std::size_t P, float* score, std::uint32_t* top) {
    for (std::size_t c = 0; c < G; ++c) {
        float acc[kBlock];
        block_dot(xt, centroids + c * dims, dims, acc);
        for (std::size_t p = 0; p < kBlock; ++p) score[c * kBlock + p] = cnorm[c] - 2.f * acc[p];
    }
    for (std::size_t p = 0; p < kBlock; ++p) {
        std::uint32_t* t = top + p * P;
        std::size_t have = 0;
        for (std::size_t c = 0; c < G; ++c) {
            const float s = score[c * kBlock + p];
            if (have == P && !(s < score[t[P - 1] * kBlock + p])) continue;
            std::size_t at = have < P ? have++ : P - 1;
            while (at > 0 && s < score[t[at - 1] * kBlock + p]) {
                t[at] = t[at - 1];
                --at;
            }
            t[at] = std::uint32_t(c);
        }
    }
}

// Labels of all n points by the grouped search: each point's nearest centre among those of the
// P groups nearest to it (ties: the nearer group's).
void grouped_search(const float* points, std::size_t n, int dims, const Groups& g, std::vector<std::uint32_t>& labels) {
    const std::size_t G = g.count;
    const std::size_t P = std::min(kProbes, G);
    // The probes of every point: (point, t) -> group. An empty group (its centroid kept from an
    // earlier step) gets an infinite norm, so it comes after every group with centres.
    std::vector<std::uint32_t> probe(n * P);
    {
        std::vector<float> cnorm = norms(g.centroids.data(), G, dims);
        for (std::size_t j = 0; j < G; ++j)
            if (g.begin[j + 1] == g.begin[j]) cnorm[j] = std::numeric_limits<float>::infinity();
        const auto blocks = static_cast<std::ptrdiff_t>((n + kBlock - 1) / kBlock);
        InterruptPoll poll;
#pragma omp parallel
        {
            std::vector<float> xt(std::size_t(dims) * kBlock), score(G * kBlock);
            std::vector<std::uint32_t> top(kBlock * P);
#pragma omp for schedule(dynamic, 4)
            for (std::ptrdiff_t b = 0; b < blocks; ++b) {
                if (poll.stop()) continue;
                std::uint32_t idx[kBlock];
                const std::size_t first = std::size_t(b) * kBlock, count = std::min(kBlock, n - first);
                for (std::size_t p = 0; p < count; ++p) idx[p] = std::uint32_t(first + p);
                transpose(points, idx, count, dims, xt.data());
                nearest_groups(xt.data(), g.centroids.data(), cnorm.data(), G, dims, P, score.data(), top.data());
                std::copy_n(top.data(), count * P, &probe[first * P]);
            }
        }
        poll.throw_if_stopped();
    }
    // The probes by group (in (point, t) order within one), and blocks of at most kBlock probes
    // of one group: each block is measured against that group's centres.
    std::vector<std::uint32_t> begin, by;
    bucket_sort(probe, G, begin, by);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> blocks;  // (group, first entry of `by`)
    for (std::size_t j = 0; j < G; ++j)
        for (std::size_t s = begin[j]; s < begin[j + 1]; s += kBlock)
            blocks.push_back({std::uint32_t(j), std::uint32_t(s)});
    std::vector<std::uint32_t> slot(n * P);
    std::vector<float> dist(n * P);
    const auto nb = static_cast<std::ptrdiff_t>(blocks.size());
    InterruptPoll poll;
#pragma omp parallel
    {
        std::vector<float> xt(std::size_t(dims) * kBlock);
#pragma omp for schedule(dynamic, 1)
        for (std::ptrdiff_t b = 0; b < nb; ++b) {
            if (poll.stop()) continue;
            const std::size_t j = blocks[std::size_t(b)].first, first = blocks[std::size_t(b)].second;
            const std::size_t count = std::min<std::size_t>(kBlock, begin[j + 1] - first);
            std::uint32_t idx[kBlock];
            for (std::size_t p = 0; p < count; ++p) idx[p] = std::uint32_t(by[first + p] / P);
            transpose(points, idx, count, dims, xt.data());
            Nearest r;
            r.start(points, idx, count, dims);
            const std::size_t s = g.begin[j];
            nearest_two(xt.data(), &g.rows[s * dims], &g.row_norms[s], g.begin[j + 1] - s, dims, std::uint32_t(s), r);
            for (std::size_t p = 0; p < count; ++p) {
                slot[by[first + p]] = r.best[p];
                dist[by[first + p]] = r.d1[p];
            }
        }
    }
    poll.throw_if_stopped();
    for (std::size_t i = 0; i < n; ++i) {
        std::size_t t = 0;
        for (std::size_t u = 1; u < P; ++u)
            if (dist[i * P + u] < dist[i * P + t]) t = u;
        labels[i] = g.centre[slot[i * P + t]];
    }
}

// Moves every centre to the mean of its points (summed in double, in index order; an emptied
// centre is re-seeded on a point drawn by `rng`).
void move_centres(const float* points, std::size_t n, int dims, const std::vector<std::uint32_t>& labels,
                  std::size_t k, SplitMix& rng, std::vector<float>& centres) {
    std::vector<double> sums(k * dims, 0.0);
    std::vector<std::size_t> counts(k, 0);
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t c = labels[i];
        ++counts[c];
        for (int d = 0; d < dims; ++d) sums[c * dims + d] += points[i * dims + d];
    }
    for (std::size_t c = 0; c < k; ++c) {
        if (counts[c] == 0) {
            const std::size_t src = rng.below(n);
            std::copy_n(points + src * dims, dims, centres.begin() + c * dims);
        } else {
            for (int d = 0; d < dims; ++d)
                centres[c * dims + d] = static_cast<float>(sums[c * dims + d] / double(counts[c]));
        }
    }
}

// fit_palette on vectors whose largest |value| is in [1, 2), with n > k.
Palette fit_scaled(const float* points, std::size_t n, int dims, std::size_t k, int iterations, std::uint64_t seed,
                   PaletteSearch how) {
    Palette p;
    p.size = k;
    SplitMix rng{seed};
    // k distinct Gaussians: a partial Fisher-Yates shuffle of the indices.
    std::vector<std::uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    for (std::size_t i = 0; i < k; ++i) std::swap(order[i], order[i + rng.below(n - i)]);
    p.centres.resize(k * dims);
    for (std::size_t c = 0; c < k; ++c)
        std::copy_n(points + std::size_t(order[c]) * dims, dims, p.centres.begin() + c * dims);
    order = {};
    p.labels.assign(n, 0);

    const bool grouped =
        how == PaletteSearch::Grouped || (how == PaletteSearch::Auto && grouped_palette_search(n, k, dims));
    if (grouped) {
        // Groups from three steps at first, then one step per iteration from the last
        // centroids (the centres move less and less).
        Groups g;
        g.count = std::max<std::size_t>(1, std::size_t(std::sqrt(double(k))));
        regroup(p.centres, k, dims, 3, g);
        grouped_search(points, n, dims, g, p.labels);
        for (int it = 0; it < iterations; ++it) {
            move_centres(points, n, dims, p.labels, k, rng, p.centres);
            regroup(p.centres, k, dims, 1, g);
            grouped_search(points, n, dims, g, p.labels);
        }
        return p;
    }

    // Lloyd's iterations with Hamerly's bounds: a point whose distance to its centre (plus that
    // centre's drift) stays below the lower bound of every other (minus the largest drift) keeps
    // its label without a search. The labels are those of a full search, up to float rounding.
    std::vector<float> u(n), l(n);
    search(points, n, dims, p.centres, k, {}, p.labels, u, l);
    std::vector<float> old, drift(k);
    std::vector<std::uint32_t> todo;
    for (int it = 0; it < iterations; ++it) {
        old = p.centres;
        move_centres(points, n, dims, p.labels, k, rng, p.centres);
        for (std::size_t c = 0; c < k; ++c) drift[c] = distance(&old[c * dims], &p.centres[c * dims], dims);
        std::size_t far = 0;  // the largest drift, and the largest of the others
        for (std::size_t c = 1; c < k; ++c)
            if (drift[c] > drift[far]) far = c;
        float second = 0.f;
        for (std::size_t c = 0; c < k; ++c)
            if (c != far) second = std::max(second, drift[c]);
        todo.clear();
        for (std::size_t i = 0; i < n; ++i) {
            const std::uint32_t a = p.labels[i];
            u[i] += drift[a];
            l[i] -= a == far ? second : drift[far];
            if (u[i] <= l[i]) continue;
            u[i] = distance(points + i * dims, &p.centres[std::size_t(a) * dims], dims);
            if (u[i] > l[i]) todo.push_back(static_cast<std::uint32_t>(i));
        }
        if (!todo.empty()) search(points, n, dims, p.centres, k, todo, p.labels, u, l);
    }
    return p;
}

}  // namespace

bool grouped_palette_search(std::size_t n, std::size_t k, int dims) {
    return k >= kGroupedMinPalette && double(n) * double(k) * double(dims) > kGroupedMinWork;
}

Palette fit_palette(const float* points, std::size_t n, int dims, std::size_t k, int iterations,
                    std::uint64_t seed, PaletteSearch how) {
    if (n <= k) {
        Palette p;
        p.size = n;
        p.centres.assign(points, points + n * std::size_t(dims));
        p.labels.resize(n);
        std::iota(p.labels.begin(), p.labels.end(), 0u);
        return p;
    }
    // The search compares squared distances in float: values from about 1e19 on overflow them
    // (every score NaN, every vector on entry 0) and values below about 1e-19 underflow them
    // (every distance 0, and subnormal arithmetic is slow). So the vectors are scaled by the
    // power of two 2^-e that puts the largest finite |value| in [1, 2): exact (up to values
    // 2^149 times below the largest, which become 0), and the same labels and, scaled back,
    // the same centres as unscaled vectors whose squares stay in range.
    const std::size_t size = n * std::size_t(dims);
    float big = 0.f;
    for (std::size_t i = 0; i < size; ++i)
        if (std::isfinite(points[i])) big = std::max(big, std::abs(points[i]));
    const int e = big > 0.f ? std::ilogb(big) : 0;
    if (e == 0) return fit_scaled(points, n, dims, k, iterations, seed, how);
    std::vector<float> scaled(size);
    for (std::size_t i = 0; i < size; ++i) scaled[i] = std::ldexp(points[i], -e);
    Palette p = fit_scaled(scaled.data(), n, dims, k, iterations, seed, how);
    for (float& c : p.centres) c = std::ldexp(c, e);
    return p;
}

}  // namespace avsplat::sog
