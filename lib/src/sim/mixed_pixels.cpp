// The mixed-pixel model: colours at depth edges mix the surfaces within a radius.
#include "sim/discontinuity.h"
#include "sim/prediction_errors.h"

#include <cmath>
#include <cstdint>
#include <utility>

namespace avsplat::sim {

std::vector<float> mix_pixels(std::vector<float>& colors, const std::vector<float>& depth, const Camera& cam,
                              double radius) {
    const int W = cam.width, H = cam.height;
    const std::size_t np = static_cast<std::size_t>(W) * H;
    std::vector<float> beta(np, 0.f);
    if (!(radius > 0.0)) return beta;
    const int r = static_cast<int>(std::floor(radius));
    std::vector<std::pair<int, int>> disc;
    for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx)
            if (dx * dx + dy * dy <= radius * radius) disc.emplace_back(dx, dy);
    const std::vector<float> original = colors;
#pragma omp parallel for schedule(static)
    for (std::int64_t ii = 0; ii < static_cast<std::int64_t>(np); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        const double d = depth[i];
        if (d <= 0.0) continue;
        const int x = static_cast<int>(i % W), y = static_cast<int>(i / W);
        const double step = depth_step(d, cam);
        int inside = 0, other = 0;
        double sum[3] = {0.0, 0.0, 0.0};
        for (const auto& [dx, dy] : disc) {
            const int qx = x + dx, qy = y + dy;
            if (qx < 0 || qx >= W || qy < 0 || qy >= H) continue;
            ++inside;
            const std::size_t q = static_cast<std::size_t>(qy) * W + qx;
            if (!other_surface(d, depth[q], step)) continue;
            ++other;
            for (int c = 0; c < 3; ++c) sum[c] += original[3 * q + c];
        }
        if (other == 0) continue;
        const double b = double(other) / inside;
        beta[i] = static_cast<float>(b);
        for (int c = 0; c < 3; ++c)
            colors[3 * i + c] = static_cast<float>((1.0 - b) * original[3 * i + c] + b * (sum[c] / other));
    }
    return beta;
}

}  // namespace avsplat::sim
