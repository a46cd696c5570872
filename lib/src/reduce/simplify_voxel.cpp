// simplify's Voxel method: occupancy-guided fusion at the voxel size whose occupied-voxel count
// meets the target (bisection on log(voxel size); avsplat/reduce/simplify.h says why and how).
#include "avsplat/fusion/fusion.h"
#include "avsplat/fusion/voxel_grid.h"
#include "reduce/simplify_methods.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <vector>

namespace avsplat::reduce_detail {

namespace {

constexpr int kMaxSteps = 64;
constexpr double kTolerance = 0.02;

std::size_t count_voxels(const GaussianCloud& c, double voxel) {
    return SparseVoxelGrid(c.means.data(), c.size(), voxel, InvalidPolicy::Raise, nullptr, "GaussianCloud.means")
        .num_voxels();
}

}  // namespace

GaussianCloud voxel_to_count(const GaussianCloud& cloud, std::size_t target, double& voxel_size, int& steps) {
    double extent = 0.0;  // max |coordinate|
    for (float v : cloud.means) extent = std::max(extent, std::abs(double(v)));
    // Every |p / v| < 1/2 at v_hi: one voxel. At v_lo every key still fits int32 (|k| <= 2^30).
    double hi = extent > 0.0 ? 4.0 * extent : 1.0;
    double lo = extent > 0.0 ? extent / double(1 << 30) : 1.0;
    steps = 0;
    double best = hi;
    std::size_t best_miss = cloud.size();  // |count - target| of `best`
    auto consider = [&](double v) {
        ++steps;
        const std::size_t c = count_voxels(cloud, v);
        const std::size_t miss = c > target ? c - target : target - c;
        // Ties go to the larger voxel: the smaller output.
        if (miss < best_miss || (miss == best_miss && v > best)) best = v, best_miss = miss;
        return c;
    };
    consider(hi);
    if (extent > 0.0 && consider(lo) > target) {
        while (steps < kMaxSteps && double(best_miss) > kTolerance * double(target) && hi / lo > 1.0 + 1e-9) {
            const double mid = std::sqrt(lo * hi);
            if (consider(mid) > target) lo = mid;
            else hi = mid;
        }
    }
    voxel_size = best;

    FusionParams params;
    params.policy = FusionPolicy::Occupancy;
    params.shape = ShapeMode::Moment;
    params.confidence_mapping = ConfidenceMapping::Logit;
    if (cloud.has_confidence()) return fuse_gaussians(cloud, best, params).cloud;
    GaussianCloud with = cloud;
    with.confidence.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
        const double o = std::clamp(double(cloud.opacities[i]), 1e-6, 1.0 - 1e-6);
        with.confidence[i] = float(std::log(o / (1.0 - o)));
    }
    GaussianCloud out = fuse_gaussians(with, best, params).cloud;
    out.confidence.clear();
    return out;
}

}  // namespace avsplat::reduce_detail
