// Lazy-greedy view coverage (avsplat/assist/view_coverage.h).
#include "avsplat/assist/view_coverage.h"

#include "avsplat/fusion/voxel_grid.h"

#include <algorithm>
#include <cmath>
#include <queue>
#include <sstream>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

[[noreturn]] void bad_value(const char* field, std::size_t pixel, int height, int width, int axis,
                            float value) {
    const std::size_t hw = std::size_t(height) * std::size_t(width);
    std::ostringstream msg;
    msg << field << "[" << pixel / hw << ", " << (pixel % hw) / std::size_t(width) << ", "
        << pixel % std::size_t(width);
    if (axis >= 0) msg << ", " << axis;
    msg << "] = " << value << " (flat pixel index " << pixel << "): expected a finite value";
    throw std::invalid_argument(msg.str());
}

// A view's candidate entry: its gain as last computed (an upper bound on its gain now).
struct Candidate {
    std::int64_t gain;
    std::int64_t view;
    // Max-heap order: larger gain first, then the smaller view index.
    bool operator<(const Candidate& o) const { return gain != o.gain ? gain < o.gain : view > o.view; }
};

}  // namespace

ViewCoverage select_views_by_coverage(const float* points, const float* confidence,
                                      const std::uint8_t* valid, int views, int height, int width,
                                      const ViewCoverageOptions& options) {
    if (views < 0 || height < 0 || width < 0)
        throw std::invalid_argument("points: dimensions must be >= 0");
    if (!(std::isfinite(options.voxel_size) && options.voxel_size > 0))
        throw std::invalid_argument("voxel_size: must be finite and > 0, got " + std::to_string(options.voxel_size));
    if (!(options.min_gain >= 0 && options.min_gain <= 1))
        throw std::invalid_argument("min_gain: must lie in [0, 1], got " + std::to_string(options.min_gain));
    if (std::isnan(options.min_confidence))
        throw std::invalid_argument("min_confidence: must not be NaN");
    const std::size_t per_view = std::size_t(height) * std::size_t(width);
    const std::size_t n = std::size_t(views) * per_view;
    if (n > 0 && points == nullptr) throw std::invalid_argument("points: missing");

    // Which pixels count. Checked here, not by the grid, so that errors name (view, row, col).
    std::vector<std::uint8_t> keep(n, 1);
    std::int64_t used = 0;
    for (std::size_t i = 0; i < n; ++i) {
        if (valid && !valid[i]) {
            keep[i] = 0;
            continue;
        }
        for (int a = 0; a < 3; ++a)
            if (!std::isfinite(points[3 * i + a])) bad_value("points", i, height, width, a, points[3 * i + a]);
        if (confidence) {
            if (!std::isfinite(confidence[i])) bad_value("confidence", i, height, width, -1, confidence[i]);
            keep[i] = confidence[i] > options.min_confidence;
        }
        used += keep[i];
    }

    ViewCoverage result;
    result.points_used = used;
    if (views == 0) return result;
    const SparseVoxelGrid grid(points, n, options.voxel_size, InvalidPolicy::Raise,
                               (confidence || valid) ? keep.data() : nullptr, "points");
    const std::vector<std::int32_t>& voxel = grid.sample_voxel();
    result.total_voxels = static_cast<std::int64_t>(grid.num_voxels());

    // The voxels of each view, sorted and unique.
    std::vector<std::vector<std::int32_t>> covers(static_cast<std::size_t>(views));
#pragma omp parallel for schedule(dynamic, 1)
    for (int s = 0; s < views; ++s) {
        std::vector<std::int32_t>& c = covers[std::size_t(s)];
        c.reserve(per_view);
        for (std::size_t i = std::size_t(s) * per_view; i < std::size_t(s + 1) * per_view; ++i)
            if (voxel[i] >= 0) c.push_back(voxel[i]);
        std::sort(c.begin(), c.end());
        c.erase(std::unique(c.begin(), c.end()), c.end());
        c.shrink_to_fit();
    }

    std::vector<std::uint8_t> covered(grid.num_voxels(), 0);
    auto gain_of = [&](std::int64_t s) {
        std::int64_t g = 0;
        for (std::int32_t v : covers[std::size_t(s)]) g += !covered[std::size_t(v)];
        return g;
    };
    std::priority_queue<Candidate> queue;
    for (int s = 0; s < views; ++s) queue.push({static_cast<std::int64_t>(covers[std::size_t(s)].size()), s});

    const std::size_t budget = options.budget == 0 ? std::size_t(views) : options.budget;
    const double threshold = options.min_gain * static_cast<double>(result.total_voxels);
    std::int64_t total = 0;
    while (!queue.empty() && result.order.size() < budget) {
        Candidate top = queue.top();
        queue.pop();
        top.gain = gain_of(top.view);
        // Every other bound is at most queue.top(): if the fresh gain still ranks first, it is
        // the greedy choice; otherwise the view goes back with its smaller bound.
        if (!queue.empty() && top < queue.top()) {
            queue.push(top);
            continue;
        }
        if (static_cast<double>(top.gain) < threshold || (top.gain == 0 && options.min_gain > 0)) break;
        for (std::int32_t v : covers[std::size_t(top.view)]) covered[std::size_t(v)] = 1;
        total += top.gain;
        result.order.push_back(top.view);
        result.gains.push_back(top.gain);
        result.coverage.push_back(total);
    }
    return result;
}

}  // namespace avsplat
