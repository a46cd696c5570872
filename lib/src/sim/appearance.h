// Private: the simulator's per-view appearance model (see sim/simulator.h, "Per-view
// appearance"): the view-dependent term of some materials and the per-view camera gains.
#pragma once

#include "avsplat/sim/simulator.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>

namespace avsplat::sim {

/// The view-dependent colour of `object` at a hit with unit normal n (facing the viewer) seen
/// along unit direction v from the hit towards the viewer, at strength 1 (RGB, white light):
/// a Blinn-Phong highlight on the sphere, a grazing sheen on the bunny, 0 elsewhere.
Eigen::Vector3d view_dependent_term(SceneObject object, const Eigen::Vector3d& n, const Eigen::Vector3d& v);

/// RGB gains of view s: exposure 2^(exposure_sigma n0) times white balance (exp(wb n1), 1,
/// exp(wb n2)), from a stream of its own seeded by (seed, s).
std::array<double, 3> view_gains(std::uint64_t seed, int view, double exposure_sigma, double white_balance_sigma);

}  // namespace avsplat::sim
