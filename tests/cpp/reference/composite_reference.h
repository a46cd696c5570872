// A brute-force compositor in double for the reduction tests: the splats come from the shared
// projection (render/shared/project_and_shade.h, itself tested against Eigen in test_render.cpp);
// every pixel then walks every visible splat in (float depth, index) order with the 3DGS rules
// written out here, without tiles, masks or chunks, and records each splat's c(p) = alpha T where
// it takes part (blended, or the splat that stops the pixel), the colour and the transmittance
// at which the pixel stopped.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/render/render.h"
#include "render/shared/project_and_shade.h"
#include "render/shared/splat_record.h"
#include "render/shared/view_params.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace avsplat::test {

struct CompositeReference {
    int width = 0, height = 0;
    std::vector<double> color;           ///< H x W x 3
    std::vector<double> t_stop;          ///< H x W: T before the splat that stopped the pixel, 0 if none
    std::vector<double> contrib_max;     ///< N
    std::vector<double> contrib_sum;     ///< N
    /// Per pixel, (Gaussian index, c(p)) for every splat with c(p) > 0.
    std::vector<std::vector<std::pair<std::uint32_t, double>>> pixel_contribs;
    double max_rgb[3] = {0.0, 0.0, 0.0}; ///< largest splat colour per channel (for the prune bound)
};

inline CompositeReference composite_reference(const GaussianCloud& c, const Camera& cam, const RenderOptions& o) {
    struct Item {
        blend::SplatRecord<double> s;
        std::uint32_t index;
    };
    const preprocess::ViewParams<double> view = preprocess::view_params<double>(cam, o, c.sh_degree);
    std::vector<Item> items;
    const int k = c.sh_coeffs();
    CompositeReference ref;
    for (std::size_t i = 0; i < c.size(); ++i) {
        Item it;
        it.index = std::uint32_t(i);
        if (preprocess::project_record(view, &c.means[3 * i], &c.scales[3 * i], &c.rotations[4 * i], c.opacities[i],
                                       &c.sh[i * std::size_t(k) * 3], it.s) == 0)
            continue;
        items.push_back(it);
        for (int ch = 0; ch < 3; ++ch) ref.max_rgb[ch] = std::max(ref.max_rgb[ch], it.s.rgb[ch]);
    }
    std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
        const float da = float(a.s.depth), db = float(b.s.depth);
        return da != db ? da < db : a.index < b.index;
    });
    ref.width = cam.width;
    ref.height = cam.height;
    const std::size_t np = std::size_t(cam.width) * std::size_t(cam.height);
    ref.color.assign(3 * np, 0.0);
    ref.t_stop.assign(np, 0.0);
    ref.contrib_max.assign(c.size(), 0.0);
    ref.contrib_sum.assign(c.size(), 0.0);
    ref.pixel_contribs.assign(np, {});
    for (int y = 0; y < cam.height; ++y) {
        for (int x = 0; x < cam.width; ++x) {
            const std::size_t p = std::size_t(y) * std::size_t(cam.width) + std::size_t(x);
            double T = 1.0, rgb[3] = {0.0, 0.0, 0.0};
            for (const Item& it : items) {
                const blend::SplatRecord<double>& s = it.s;
                if (x < s.x_min || x > s.x_max || y < s.y_min || y > s.y_max) continue;
                const double dx = x + 0.5 - s.mean_x, dy = y + 0.5 - s.mean_y;
                const double power = -0.5 * (s.conic_a * dx * dx + s.conic_c * dy * dy) - s.conic_b * dx * dy;
                if (power > 0.0) continue;
                const double alpha = std::min(0.99, s.opacity * std::exp(power));
                if (alpha < double(o.alpha_threshold)) continue;
                const double cp = alpha * T;
                ref.contrib_max[it.index] = std::max(ref.contrib_max[it.index], cp);
                ref.contrib_sum[it.index] += cp;
                ref.pixel_contribs[p].push_back({it.index, cp});
                if (T * (1.0 - alpha) < double(o.transmittance_stop)) {
                    ref.t_stop[p] = T;
                    break;
                }
                for (int ch = 0; ch < 3; ++ch) rgb[ch] += cp * s.rgb[ch];
                T *= 1.0 - alpha;
            }
            for (int ch = 0; ch < 3; ++ch) ref.color[3 * p + ch] = rgb[ch] + T * double(o.background[ch]);
        }
    }
    return ref;
}

}  // namespace avsplat::test
