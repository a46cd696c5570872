// The SOG writer's 1D codebooks (codebook.h): 256 shared levels for one kind of value.
#include "io/sog/codebook.h"

#include "io/sog/sog_meta.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace avsplat::sog {

namespace {

void finish(Codebook1D& cb) {
    cb.mids_.resize(cb.levels.size() - 1);
    for (std::size_t i = 0; i + 1 < cb.levels.size(); ++i)
        cb.mids_[i] = 0.5 * (double(cb.levels[i]) + double(cb.levels[i + 1]));
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

}  // namespace avsplat::sog
