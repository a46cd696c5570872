// The SOG writer's SH palette (codebook.h): k-means of the SH-rest vectors.
#include "io/sog/codebook.h"

#include "common/cpu_dispatch.h"

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

// For each of the kBlock points of `xt` (dims x kBlock, transposed), the nearest and the second
// nearest of the k centres by ||c||^2 - 2 x.c (the point's own norm is added by the caller).
// Each point's result depends on its own coordinates only, not on the other points of the block,
// so the grouping into blocks (and threads) cannot change it.
AVSPLAT_CLONES_V3
void nearest_two(const float* xt, const float* centres, const float* cnorm, std::size_t k, int dims,
                 std::uint32_t* best, float* d1, float* d2) {
    float b1[kBlock], b2[kBlock];
    std::uint32_t bi[kBlock];
    for (std::size_t p = 0; p < kBlock; ++p) {
        b1[p] = b2[p] = std::numeric_limits<float>::infinity();
        bi[p] = 0;
    }
    for (std::size_t c = 0; c < k; ++c) {
        float acc[kBlock] = {};
        const float* cc = centres + c * dims;
        for (int d = 0; d < dims; ++d) {
            const float v = cc[d];
            const float* row = xt + std::size_t(d) * kBlock;
            for (std::size_t p = 0; p < kBlock; ++p) acc[p] += row[p] * v;
        }
        const float cn = cnorm[c];
        const auto ci = static_cast<std::uint32_t>(c);
        for (std::size_t p = 0; p < kBlock; ++p) {
            const float s = cn - 2.f * acc[p];
            const bool lt = s < b1[p];
            b2[p] = lt ? b1[p] : std::min(b2[p], s);
            b1[p] = lt ? s : b1[p];
            bi[p] = lt ? ci : bi[p];
        }
    }
    for (std::size_t p = 0; p < kBlock; ++p) {
        best[p] = bi[p];
        d1[p] = b1[p];
        d2[p] = b2[p];
    }
}

float distance(const float* a, const float* b, int dims) {
    double s = 0;
    for (int d = 0; d < dims; ++d) s += (double(a[d]) - b[d]) * (double(a[d]) - b[d]);
    return static_cast<float>(std::sqrt(s));
}

// Nearest centre of the points `which` (all when empty), with Hamerly's bounds: u the distance to
// the assigned centre, l a lower bound of the distance to any other.
void search(const float* points, std::size_t n, int dims, const std::vector<float>& centres, std::size_t k,
            const std::vector<std::uint32_t>& which, std::vector<std::uint32_t>& labels,
            std::vector<float>& u, std::vector<float>& l) {
    std::vector<float> cnorm(k);
    for (std::size_t c = 0; c < k; ++c) {
        double s = 0;
        for (int d = 0; d < dims; ++d) s += double(centres[c * dims + d]) * centres[c * dims + d];
        cnorm[c] = static_cast<float>(s);
    }
    const std::size_t m = which.empty() ? n : which.size();
    const auto blocks = static_cast<std::ptrdiff_t>((m + kBlock - 1) / kBlock);
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t b = 0; b < blocks; ++b) {
        std::vector<float> xt(std::size_t(dims) * kBlock, 0.f);
        std::size_t idx[kBlock];
        const std::size_t first = std::size_t(b) * kBlock, count = std::min(kBlock, m - first);
        for (std::size_t p = 0; p < count; ++p) {
            idx[p] = which.empty() ? first + p : which[first + p];
            for (int d = 0; d < dims; ++d) xt[std::size_t(d) * kBlock + p] = points[idx[p] * dims + d];
        }
        std::uint32_t best[kBlock];
        float d1[kBlock], d2[kBlock];
        nearest_two(xt.data(), centres.data(), cnorm.data(), k, dims, best, d1, d2);
        for (std::size_t p = 0; p < count; ++p) {
            const std::size_t i = idx[p];
            double xn = 0;
            for (int d = 0; d < dims; ++d) xn += double(points[i * dims + d]) * points[i * dims + d];
            labels[i] = best[p];
            u[i] = std::sqrt(std::max(0.0, xn + d1[p]));
            l[i] = std::sqrt(std::max(0.0, xn + d2[p]));
        }
    }
}

}  // namespace

Palette fit_palette(const float* points, std::size_t n, int dims, std::size_t k, int iterations,
                    std::uint64_t seed) {
    Palette p;
    if (n <= k) {
        p.size = n;
        p.centres.assign(points, points + n * std::size_t(dims));
        p.labels.resize(n);
        std::iota(p.labels.begin(), p.labels.end(), 0u);
        return p;
    }
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

    // Lloyd's iterations with Hamerly's bounds: a point whose distance to its centre (plus that
    // centre's drift) stays below the lower bound of every other (minus the largest drift) keeps
    // its label without a search. The labels are those of a full search, up to float rounding.
    p.labels.assign(n, 0);
    std::vector<float> u(n), l(n);
    search(points, n, dims, p.centres, k, {}, p.labels, u, l);
    std::vector<double> sums(k * dims);
    std::vector<std::size_t> counts(k);
    std::vector<float> old, drift(k);
    std::vector<std::uint32_t> todo;
    for (int it = 0; it < iterations; ++it) {
        std::fill(sums.begin(), sums.end(), 0.0);
        std::fill(counts.begin(), counts.end(), 0);
        for (std::size_t i = 0; i < n; ++i) {
            const std::size_t c = p.labels[i];
            ++counts[c];
            for (int d = 0; d < dims; ++d) sums[c * dims + d] += points[i * dims + d];
        }
        old = p.centres;
        for (std::size_t c = 0; c < k; ++c) {
            if (counts[c] == 0) {
                const std::size_t src = rng.below(n);
                std::copy_n(points + src * dims, dims, p.centres.begin() + c * dims);
            } else {
                for (int d = 0; d < dims; ++d)
                    p.centres[c * dims + d] = static_cast<float>(sums[c * dims + d] / double(counts[c]));
            }
            drift[c] = distance(&old[c * dims], &p.centres[c * dims], dims);
        }
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

}  // namespace avsplat::sog
