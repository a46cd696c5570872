// Random scenes and cameras for the reduction tests (prune, reduce_sh, contributions): Gaussians
// in a unit ball around the origin (some far outside it, as floaters), random rotations,
// log-uniform scales, opacities spread over [0, 1] with exact 0 and 1 among them, SH of a given
// degree whose higher bands are scaled by `band_scale`; cameras on a sphere looking at the origin.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace avsplat::test {

inline GaussianCloud reduction_scene(std::size_t n, int degree, std::uint32_t seed, double band_scale = 0.3,
                                     double scale_lo = 0.01, double scale_hi = 0.4) {
    GaussianCloud c(n, degree);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0), u01(0.0, 1.0), ls(std::log(scale_lo), std::log(scale_hi));
    std::normal_distribution<double> g(0.0, 1.0);
    const int k = c.sh_coeffs();
    for (std::size_t i = 0; i < n; ++i) {
        const double spread = i % 10 == 0 ? 6.0 : 1.0;  // every tenth one a floater, often outside the views
        for (int j = 0; j < 3; ++j) c.means[3 * i + j] = float(spread * u(rng));
        for (int j = 0; j < 3; ++j) c.scales[3 * i + j] = float(std::exp(ls(rng)));
        for (int j = 0; j < 4; ++j) c.rotations[4 * i + j] = float(g(rng));
        const double o = u01(rng);
        c.opacities[i] = float(i % 17 == 0 ? 0.0 : i % 13 == 0 ? 1.0 : o * o);
        for (int j = 0; j < k * 3; ++j) c.sh[i * std::size_t(k) * 3 + std::size_t(j)] = float((j < 3 ? 1.0 : band_scale) * g(rng));
    }
    return c;
}

/// A camera `distance` from the origin in a random direction, looking at it.
inline Camera reduction_camera(std::mt19937& rng, int width = 48, int height = 36, double distance = 3.0) {
    std::normal_distribution<double> g(0.0, 1.0);
    Eigen::Vector3d eye(g(rng), g(rng), g(rng));
    eye = distance * eye.normalized();
    const Eigen::Vector3d up = std::abs(eye.normalized().y()) > 0.9 ? Eigen::Vector3d(1, 0, 0) : Eigen::Vector3d(0, 1, 0);
    return Camera::look_at(eye, Eigen::Vector3d::Zero(), up, 60.0, width, height);
}

}  // namespace avsplat::test
