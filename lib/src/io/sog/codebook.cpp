#include "io/sog/codebook.h"

#include "io/sog/sog_meta.h"

#include <nanoflann.hpp>

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

void finish(Codebook1D& cb) {
    cb.mids_.resize(cb.levels.size() - 1);
    for (std::size_t i = 0; i + 1 < cb.levels.size(); ++i)
        cb.mids_[i] = 0.5 * (double(cb.levels[i]) + double(cb.levels[i + 1]));
}

// nanoflann's dataset interface over the palette's centres.
struct Centres {
    const float* data;
    std::size_t n;
    int dims;
    std::size_t kdtree_get_point_count() const { return n; }
    float kdtree_get_pt(std::size_t i, std::size_t d) const { return data[i * dims + d]; }
    template <class BBox>
    bool kdtree_get_bbox(BBox&) const { return false; }
};

using CentreTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, Centres, float>,
                                                       Centres, -1, std::uint32_t>;

void assign(const float* points, std::size_t n, int dims, const std::vector<float>& centres, std::size_t k,
            std::vector<std::uint32_t>& labels) {
    const Centres data{centres.data(), k, dims};
    CentreTree tree(dims, data,
                    nanoflann::KDTreeSingleIndexAdaptorParams(
                        10, nanoflann::KDTreeSingleIndexAdaptorFlags::SkipInitialBuildIndex));
    tree.buildIndex();
    const auto count = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(dynamic, 1024)
    for (std::ptrdiff_t i = 0; i < count; ++i) {
        std::uint32_t idx = 0;
        float d2 = 0.f;
        tree.knnSearch(points + std::size_t(i) * dims, 1, &idx, &d2);
        labels[std::size_t(i)] = idx;
    }
}

}  // namespace

std::uint8_t Codebook1D::label(float v) const {
    return static_cast<std::uint8_t>(std::upper_bound(mids_.begin(), mids_.end(), double(v)) - mids_.begin());
}

Codebook1D fit_codebook(const std::vector<float>& values) {
    constexpr std::size_t K = kCodebookSize;
    std::vector<float> sorted;
    sorted.reserve(values.size());
    bool neg_inf = false;
    for (float v : values) {
        if (std::isfinite(v)) sorted.push_back(v);
        else if (v < 0) neg_inf = true;
    }
    std::sort(sorted.begin(), sorted.end());
    const std::size_t k = K - (neg_inf ? 1 : 0);  // levels for the finite values

    std::vector<float> distinct;
    for (float v : sorted)
        if (distinct.empty() || distinct.back() != v) distinct.push_back(v);

    std::vector<float> levels;
    if (distinct.size() <= k) {
        levels = distinct;  // exact
    } else {
        // Start half way between the quantiles (where the values are dense) and even steps over
        // the range (so the tails have levels too; Lloyd alone moves levels into a sparse tail
        // only slowly). Strictly increasing, so no two levels start equal.
        const std::size_t n = sorted.size();
        const double lo = sorted.front(), hi = sorted.back();
        std::vector<double> c(k);
        for (std::size_t i = 0; i < k; ++i)
            c[i] = 0.5 * double(sorted[std::min(n - 1, (2 * i + 1) * n / (2 * k))]) +
                   0.5 * (lo + (hi - lo) * (double(i) + 0.5) / double(k));
        std::vector<double> prefix(n + 1, 0.0);
        for (std::size_t i = 0; i < n; ++i) prefix[i + 1] = prefix[i] + sorted[i];
        std::vector<std::size_t> bound(k + 1);
        for (int it = 0; it < kCodebookIterations; ++it) {
            bound[0] = 0;
            bound[k] = n;
            for (std::size_t i = 1; i < k; ++i) {
                const double mid = 0.5 * (c[i - 1] + c[i]);
                bound[i] = static_cast<std::size_t>(
                    std::lower_bound(sorted.begin(), sorted.end(), mid,
                                     [](float a, double b) { return double(a) < b; }) - sorted.begin());
            }
            bool moved = false;
            for (std::size_t i = 0; i < k; ++i) {
                if (bound[i + 1] <= bound[i]) continue;  // empty: stays
                const double mean = (prefix[bound[i + 1]] - prefix[bound[i]]) / double(bound[i + 1] - bound[i]);
                if (mean != c[i]) moved = true;
                c[i] = mean;
            }
            if (!moved) break;
        }
        levels.resize(k);
        for (std::size_t i = 0; i < k; ++i) levels[i] = static_cast<float>(c[i]);
        std::sort(levels.begin(), levels.end());
    }

    Codebook1D cb;
    if (neg_inf) cb.levels.push_back((sorted.empty() ? 0.f : sorted.front()) - 20.f);
    cb.levels.insert(cb.levels.end(), levels.begin(), levels.end());
    const float pad = cb.levels.empty() ? 0.f : cb.levels.back();
    cb.levels.resize(K, pad);
    finish(cb);
    return cb;
}

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

    p.labels.assign(n, 0);
    std::vector<double> sums(k * dims);
    std::vector<std::size_t> counts(k);
    for (int it = 0; it < iterations; ++it) {
        assign(points, n, dims, p.centres, k, p.labels);
        std::fill(sums.begin(), sums.end(), 0.0);
        std::fill(counts.begin(), counts.end(), 0);
        for (std::size_t i = 0; i < n; ++i) {
            const std::size_t c = p.labels[i];
            ++counts[c];
            for (int d = 0; d < dims; ++d) sums[c * dims + d] += points[i * dims + d];
        }
        for (std::size_t c = 0; c < k; ++c) {
            if (counts[c] == 0) {
                const std::size_t src = rng.below(n);
                std::copy_n(points + src * dims, dims, p.centres.begin() + c * dims);
                continue;
            }
            for (int d = 0; d < dims; ++d)
                p.centres[c * dims + d] = static_cast<float>(sums[c * dims + d] / double(counts[c]));
        }
    }
    assign(points, n, dims, p.centres, k, p.labels);
    return p;
}

}  // namespace avsplat::sog
