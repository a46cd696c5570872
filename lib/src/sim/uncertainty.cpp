// Where a feed-forward model is unsure: far, grazing, textureless and near depth edges.
#include "sim/discontinuity.h"
#include "sim/prediction_errors.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace avsplat::sim {

namespace {

constexpr double kTextureStep = 0.1;  // a colour step to a neighbour that counts as texture
constexpr int kEdgeRadius = 2;        // pixels (Chebyshev) within which an edge counts

}  // namespace

std::vector<float> uncertainty(const std::vector<float>& depth, const std::vector<float>& cos,
                               const std::vector<float>& reference, const Camera& cam) {
    const int W = cam.width, H = cam.height;
    const std::size_t np = static_cast<std::size_t>(W) * H;
    std::vector<float> u(np, 0.f);
    std::vector<float> valid_depth;
    for (float d : depth)
        if (d > 0.f) valid_depth.push_back(d);
    if (valid_depth.empty()) return u;
    const auto mid = valid_depth.begin() + static_cast<std::ptrdiff_t>(valid_depth.size() / 2);
    std::nth_element(valid_depth.begin(), mid, valid_depth.end());
    const double median = *mid;
#pragma omp parallel for schedule(static)
    for (std::int64_t ii = 0; ii < static_cast<std::int64_t>(np); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        const double d = depth[i];
        if (d <= 0.0) continue;
        const int x = static_cast<int>(i % W), y = static_cast<int>(i / W);
        const double step = depth_step(d, cam);
        const double far = std::min(1.0, std::max(0.0, d / median - 1.0));
        const double grazing = 1.0 - std::min(1.0, double(cos[i]));
        double g = 0.0;
        const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
        for (int k = 0; k < 4; ++k) {
            if (nx[k] < 0 || nx[k] >= W || ny[k] < 0 || ny[k] >= H) continue;
            const std::size_t q = static_cast<std::size_t>(ny[k]) * W + nx[k];
            if (other_surface(d, depth[q], step)) continue;
            for (int c = 0; c < 3; ++c) g = std::max(g, double(std::abs(reference[3 * q + c] - reference[3 * i + c])));
        }
        const double textureless = 1.0 - std::min(1.0, g / kTextureStep);
        double edge = 0.0;
        for (int dy = -kEdgeRadius; dy <= kEdgeRadius && edge == 0.0; ++dy)
            for (int dx = -kEdgeRadius; dx <= kEdgeRadius; ++dx) {
                const int qx = x + dx, qy = y + dy;
                if (qx < 0 || qx >= W || qy < 0 || qy >= H) continue;
                if (other_surface(d, depth[static_cast<std::size_t>(qy) * W + qx], step)) {
                    edge = 1.0;
                    break;
                }
            }
        u[i] = static_cast<float>(1.0 + far + grazing + textureless + edge);
    }
    return u;
}

}  // namespace avsplat::sim
