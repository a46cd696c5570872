// Clouds and references shared by the simplify tests (test_simplify.cpp, test_merge_cost.cpp).
#pragma once

#include "avsplat/core/gaussians.h"

#include <Eigen/Core>

#include <cmath>
#include <cstddef>
#include <random>
#include <vector>

namespace simplify_test {

using avsplat::GaussianCloud;

constexpr double kPi = 3.14159265358979323846;

// Thomsen's ellipsoid surface area written out again for the reference.
inline double area_ref(double a, double b, double c) {
    const double p = 1.6075;
    return 4.0 * kPi * std::pow((std::pow(a * b, p) + std::pow(a * c, p) + std::pow(b * c, p)) / 3.0, 1.0 / p);
}

// Clusters of Gaussians like a fused scene: n Gaussians around `clusters` centres, SH degree 1.
inline GaussianCloud clustered(std::size_t n, unsigned seed, int clusters = 50) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f), pos(0.f, 1.f);
    std::normal_distribution<float> nrm(0.f, 1.f);
    std::vector<Eigen::Vector3f> centres(static_cast<std::size_t>(clusters));
    for (auto& c : centres) c = Eigen::Vector3f(u(rng), u(rng), u(rng)) * 2.f;
    GaussianCloud c(n, 1);
    for (std::size_t i = 0; i < n; ++i) {
        const Eigen::Vector3f& m = centres[i % centres.size()];
        for (int a = 0; a < 3; ++a) {
            c.means[3 * i + a] = m[a] + 0.05f * nrm(rng);
            c.scales[3 * i + a] = 0.005f + 0.02f * pos(rng);
        }
        Eigen::Vector4f q(nrm(rng), nrm(rng), nrm(rng), nrm(rng));
        q.normalize();
        for (int a = 0; a < 4; ++a) c.rotations[4 * i + a] = q[a];
        c.opacities[i] = 0.05f + 0.9f * pos(rng);
        for (std::size_t k = 0; k < 12; ++k) c.sh[12 * i + k] = 0.5f * u(rng);
    }
    return c;
}

// clustered() with every third Gaussian flat, every fifth a needle and every seventh of opacity 0
// or 1: the shapes whose merge costs take the stiff paths.
inline GaussianCloud stiff_clustered(std::size_t n, unsigned seed, int clusters, unsigned opacity_seed) {
    GaussianCloud c = clustered(n, seed, clusters);
    std::mt19937 rng(opacity_seed);
    std::uniform_real_distribution<float> u(0.f, 1.f);
    for (std::size_t i = 0; i < c.size(); i += 3) c.scales[3 * i + std::size_t(i % 3)] *= 1e-3f;  // flat
    for (std::size_t i = 1; i < c.size(); i += 5) c.scales[3 * i + std::size_t(i % 3)] *= 50.f;   // needles
    for (std::size_t i = 2; i < c.size(); i += 7) c.opacities[i] = u(rng) < 0.5f ? 0.f : 1.f;
    return c;
}

}  // namespace simplify_test
