// Helpers shared by the simulator's tests: test_simulator.cpp (no Open3D, so it also runs under
// the sanitizers) and test_simulator_open3d.cpp (the checks against Open3D's distance queries).
#pragma once

#include "avsplat/sim/simulator.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <vector>

namespace sim_test {

using avsplat::Camera;
using avsplat::SimulatorOptions;
namespace scene = avsplat::default_scene;

inline SimulatorOptions small(int views = 3, int width = 40, int height = 30) {
    SimulatorOptions o;
    o.views = views;
    o.width = width;
    o.height = height;
    o.target_views = std::min(2, views - 1);
    return o;
}

inline SimulatorOptions noise_free(SimulatorOptions o) {
    o.pose_noise_rot_deg = 0.0;
    o.pose_noise_trans = 0.0;
    o.depth_noise = 0.0;
    o.flying_pixels = false;
    return o;
}

inline Eigen::Vector3d at(const std::vector<float>& v, std::size_t i) {
    return Eigen::Vector3d(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
}

inline const Eigen::Vector3d kCenter(scene::kSphereCenter[0], scene::kSphereCenter[1], scene::kSphereCenter[2]);

inline Eigen::Vector3d pixel_ray(const Camera& c, double x, double y) {
    return c.camera_to_world().block<3, 3>(0, 0) * Eigen::Vector3d((x - c.cx) / c.fx, (y - c.cy) / c.fy, 1.0);
}

}  // namespace sim_test
