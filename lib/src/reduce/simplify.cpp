// simplify: the budget (count, ratio or rendered error), the canonical order and the error
// measurement around the two methods (simplify_merge.cpp, simplify_voxel.cpp).
#include "avsplat/reduce/simplify.h"

#include "core/progress_report.h"

#include "avsplat/core/interrupt.h"
#include "common/order_key.h"
#include "common/radix_sort.h"
#include "reduce/simplify_methods.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// The rows of `c` sorted by the bits of every field (mean first), so that the methods see the
/// same cloud whatever the input order: order[i] is the row of `c` that comes i-th. Identical
/// rows are interchangeable. A radix sort of (key of x, row) integers first, then the full
/// comparison within runs of equal x (rare): the same order as sorting by the full comparison
/// alone, which took 5 % of a merge to 1/2.
std::vector<std::size_t> canonical_order(const GaussianCloud& c) {
    const std::size_t n = c.size();
    const std::size_t k3 = std::size_t(c.sh_coeffs()) * 3;
    auto less_run = [](const float* x, const float* y, std::size_t len, int& verdict) {
        for (std::size_t t = 0; t < len; ++t) {
            const std::uint32_t a = float_order_key(x[t]), b = float_order_key(y[t]);
            if (a != b) {
                verdict = a < b ? -1 : 1;
                return;
            }
        }
    };
    auto less = [&](std::size_t i, std::size_t j) {
        int v = 0;
        less_run(&c.means[3 * i], &c.means[3 * j], 3, v);
        if (!v) less_run(&c.scales[3 * i], &c.scales[3 * j], 3, v);
        if (!v) less_run(&c.rotations[4 * i], &c.rotations[4 * j], 4, v);
        if (!v) less_run(&c.opacities[i], &c.opacities[j], 1, v);
        if (!v) less_run(&c.sh[k3 * i], &c.sh[k3 * j], k3, v);
        if (!v && c.has_confidence()) less_run(&c.confidence[i], &c.confidence[j], 1, v);
        for (std::size_t e = 0; !v && e < c.extras.size(); ++e)
            less_run(&c.extras[e].values[i], &c.extras[e].values[j], 1, v);
        return v < 0;
    };
    std::vector<std::size_t> order(n);
    if (n > 0xFFFFFFFFu) {  // rows do not fit the low half of the keys
        std::iota(order.begin(), order.end(), std::size_t(0));
        std::sort(order.begin(), order.end(), less);
        return order;
    }
    std::vector<std::uint64_t> keyed(n), scratch(n);
    for (std::size_t i = 0; i < n; ++i) keyed[i] = (std::uint64_t(float_order_key(c.means[3 * i])) << 32) | i;
    const std::uint64_t* sorted = radix_sort(keyed.data(), scratch.data(), n, 32, 64);  // stable
    for (std::size_t t = 0; t < n; ++t) order[t] = std::size_t(sorted[t] & 0xFFFFFFFFu);
    for (std::size_t t = 0; t < n;) {
        std::size_t u = t + 1;
        while (u < n && (sorted[u] >> 32) == (sorted[t] >> 32)) ++u;
        if (u - t > 1) std::sort(order.begin() + std::ptrdiff_t(t), order.begin() + std::ptrdiff_t(u), less);
        t = u;
    }
    return order;
}

struct Renders {
    std::vector<std::vector<float>> color;
};

Renders render_all(const GaussianCloud& c, const std::vector<Camera>& cameras, const RenderOptions& o) {
    Renders r;
    for (const Camera& cam : cameras) r.color.push_back(render(c, cam, o).color);
    return r;
}

/// RMSE of rendered colour against `reference` over every pixel, channel and camera.
double render_error(const GaussianCloud& c, const std::vector<Camera>& cameras, const RenderOptions& o,
                    const Renders& reference) {
    double sum = 0.0;
    std::size_t count = 0;
    for (std::size_t v = 0; v < cameras.size(); ++v) {
        const std::vector<float> color = render(c, cameras[v], o).color;
        const std::vector<float>& ref = reference.color[v];
        for (std::size_t p = 0; p < color.size(); ++p) {
            const double d = double(color[p]) - double(ref[p]);
            sum += d * d;
        }
        count += color.size();
    }
    return count ? std::sqrt(sum / double(count)) : 0.0;
}

/// The method on the rows of `cloud` in canonical `order`, to `target` Gaussians. (Merge reads
/// the rows through `order` and copies the cloud once, in its own order; voxel gets the
/// canonical copy.)
SimplifyResult run(const GaussianCloud& cloud, const std::vector<std::size_t>& order, std::size_t target,
                   SimplifyMethod method) {
    SimplifyResult r;
    r.input_count = cloud.size();
    r.target_count = target;
    r.method = method;
    r.voxel_size = kNaN;
    r.error = kNaN;
    if (target >= cloud.size()) {
        r.cloud = select(cloud, order);
    } else if (method == SimplifyMethod::Merge) {
        r.cloud = reduce_detail::merge_to_count(cloud, order, target, r.iterations);  // reports per round
    } else {
        ProgressReport report(cloud.size() - target);  // Gaussians removed: all at once
        r.cloud = reduce_detail::voxel_to_count(select(cloud, order), target, r.voxel_size, r.iterations);
        report.finish();
    }
    // Merged or fused Gaussians of an antialiased scene are rendered with its 2D filter too (the
    // methods build new clouds, which start without the flag).
    r.cloud.antialiased = cloud.antialiased;
    r.output_count = r.cloud.size();
    return r;
}

}  // namespace

void validate(const SimplifyOptions& o) {
    const int budgets = int(o.target_count.has_value()) + int(o.ratio.has_value()) + int(o.max_error.has_value());
    if (budgets != 1)
        throw std::invalid_argument("SimplifyOptions: give exactly one of target_count, ratio and max_error (got " +
                                    std::to_string(budgets) + ")");
    if (o.target_count && *o.target_count < 1)
        throw std::invalid_argument("SimplifyOptions.target_count: must be >= 1, got 0");
    if (o.ratio && !(*o.ratio > 0.0 && *o.ratio <= 1.0))
        throw std::invalid_argument("SimplifyOptions.ratio: must be in (0, 1], got " + std::to_string(*o.ratio));
    if (o.max_error && !(*o.max_error > 0.0 && std::isfinite(*o.max_error)))
        throw std::invalid_argument("SimplifyOptions.max_error: must be finite and > 0, got " +
                                    std::to_string(*o.max_error));
    if (o.method != SimplifyMethod::Merge && o.method != SimplifyMethod::Voxel)
        throw std::invalid_argument("SimplifyOptions.method: unknown value " + std::to_string(int(o.method)));
}

SimplifyResult simplify(const GaussianCloud& cloud, const SimplifyOptions& options, const std::vector<Camera>& cameras) {
    validate(options);
    validate(cloud);
    if (options.max_error && cameras.empty())
        throw std::invalid_argument("simplify: max_error needs cameras to measure the rendered error at");
    for (std::size_t v = 0; v < cameras.size(); ++v) {
        try {
            cameras[v].validate();
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument("simplify: cameras[" + std::to_string(v) + "]: " + e.what());
        }
    }
    const std::size_t n = cloud.size();
    const std::vector<std::size_t> order = canonical_order(cloud);
    const Renders reference =
        cameras.empty() ? Renders{} : render_all(select(cloud, order), cameras, options.render);

    if (!options.max_error) {
        std::size_t target = n;
        if (options.target_count) target = *options.target_count;
        if (options.ratio) target = std::max<std::size_t>(1, std::size_t(std::llround(*options.ratio * double(n))));
        SimplifyResult r = run(cloud, order, target, options.method);
        if (!cameras.empty()) r.error = render_error(r.cloud, cameras, options.render, reference);
        return r;
    }

    // max_error: the smallest count whose error is <= max_error, by bisection on log(count).
    // `lo` always meets the bound (the input does, with error 0); `hi` does not.
    const double bound = *options.max_error;
    ProgressReport report(kMaxErrorSearches);  // counts tried; a search that ends early jumps to the end
    SimplifyResult best = run(cloud, order, n, options.method);
    best.error = 0.0;
    int searches = 0;
    if (n > 1) {
        const auto tried = [&] {
            ++searches;
            if (options.progress) options.progress(searches, kMaxErrorSearches);
            report.set(std::uint64_t(searches));
        };
        SimplifyResult one = run(cloud, order, 1, options.method);
        tried();
        one.error = render_error(one.cloud, cameras, options.render, reference);
        if (one.error <= bound) {
            best = std::move(one);
        } else {
            std::size_t lo = n, hi = 1;
            for (int step = 0; step < kMaxErrorSearches - 1 && lo - hi > 1 && double(lo) > 1.02 * double(hi); ++step) {
                std::size_t mid = std::size_t(std::llround(std::sqrt(double(lo) * double(hi))));
                mid = std::clamp(mid, hi + 1, lo - 1);
                SimplifyResult r = run(cloud, order, mid, options.method);
                tried();
                r.error = render_error(r.cloud, cameras, options.render, reference);
                if (r.error <= bound) {
                    lo = mid;
                    best = std::move(r);
                } else {
                    hi = mid;
                }
            }
        }
    }
    best.searches = searches;
    report.finish();
    return best;
}

}  // namespace avsplat
