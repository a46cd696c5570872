// Private: the simulator's one rule for "another surface" between neighbouring pixels, shared by
// the flying-pixel, mixed-pixel and uncertainty models (sim/simulator.h).
#pragma once

#include "avsplat/core/camera.h"

#include <cmath>

namespace avsplat::sim {

/// The depth step between neighbouring pixels that no surface makes unless it is slanted by
/// more than about 83 degrees to the ray: 8 d / sqrt(fx fy) at depth d.
inline double depth_step(double depth, const Camera& cam) { return 8.0 * depth / std::sqrt(cam.fx * cam.fy); }

/// Whether a pixel of true depth `other` (0: background) lies on another surface than one of
/// depth `depth` whose depth_step is `step`.
inline bool other_surface(double depth, double other, double step) {
    return other <= 0.0 || std::abs(other - depth) > step;
}

}  // namespace avsplat::sim
