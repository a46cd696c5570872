// The simulator's per-view appearance model: specular / sheen terms and camera gains.
#include "sim/appearance.h"

#include "sim/random.h"

#include <cmath>

namespace avsplat::sim {

namespace {

// Light direction (towards the light): above the scene, from the side of the cameras.
const Eigen::Vector3d kLight = Eigen::Vector3d(-0.4, -0.6, 1.0).normalized();
constexpr double kSphereShininess = 50.0;
constexpr double kSheenExponent = 4.0;
constexpr double kSheenStrength = 0.5;
// Stream tag of the gains, distinct from the other per-view streams.
constexpr std::uint64_t kGainStream = 0xA99EA4A7CEull;

}  // namespace

Eigen::Vector3d view_dependent_term(SceneObject object, const Eigen::Vector3d& n, const Eigen::Vector3d& v) {
    double k = 0.0;
    if (object == SceneObject::Sphere) {
        if (n.dot(kLight) > 0.0) {
            const Eigen::Vector3d h = (kLight + v).normalized();
            k = std::pow(std::max(0.0, n.dot(h)), kSphereShininess);
        }
    } else if (object == SceneObject::Bunny) {
        k = kSheenStrength * std::pow(1.0 - std::min(1.0, std::abs(n.dot(v))), kSheenExponent);
    }
    return Eigen::Vector3d::Constant(k);
}

std::array<double, 3> view_gains(std::uint64_t seed, int view, double exposure_sigma, double white_balance_sigma) {
    Rng rng(splitmix64(seed ^ splitmix64(kGainStream + static_cast<std::uint64_t>(view))));
    const double n0 = rng.normal(), n1 = rng.normal(), n2 = rng.normal();
    const double exposure = std::exp2(exposure_sigma * n0);
    return {exposure * std::exp(white_balance_sigma * n1), exposure, exposure * std::exp(white_balance_sigma * n2)};
}

}  // namespace avsplat::sim
