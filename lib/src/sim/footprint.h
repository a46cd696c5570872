// Private: the pixel footprint of the simulator's camera (sim/simulator.h, "Pixel footprint"):
// the unit pixel square convolved with an isotropic Gaussian of std sigma pixels, sampled on the
// supersample grid. Separable: the weight of a sample at offset (dx, dy) from the pixel centre
// is w(dx) w(dy), w(d) = Phi((d + 1/2) / sigma) - Phi((d - 1/2) / sigma) (the box for sigma = 0).
#pragma once

#include <cmath>
#include <vector>

namespace avsplat::sim {

struct FootprintKernel {
    int margin = 0;              // pixels of support beyond the pixel on each side
    std::vector<double> weight;  // ss (1 + 2 margin) weights, sample offsets from the first
                                 // sample of the pixel's left margin, in sample order
};

// Samples of a pixel sit at x + (a + 0.5) / ss, a in [-margin ss, (1 + margin) ss).
inline FootprintKernel footprint_kernel(int ss, double sigma) {
    FootprintKernel k;
    k.margin = sigma > 0.0 ? static_cast<int>(std::ceil(4.0 * sigma)) : 0;
    const int n = ss * (1 + 2 * k.margin);
    k.weight.resize(n);
    for (int j = 0; j < n; ++j) {
        // Offset of the sample from the pixel centre, in pixels.
        const double d = (j - k.margin * ss + 0.5) / ss - 0.5;
        if (sigma > 0.0) {
            const double s = sigma * std::sqrt(2.0);
            k.weight[j] = 0.5 * (std::erf((d + 0.5) / s) - std::erf((d - 0.5) / s));
        } else {
            k.weight[j] = 1.0;  // every sample of the pixel (|d| < 1/2), none beyond (margin 0)
        }
    }
    return k;
}

}  // namespace avsplat::sim
