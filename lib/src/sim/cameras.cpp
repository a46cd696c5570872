// The simulator's cameras: input views on an arc, held-out targets between them.
#include "avsplat/sim/simulator.h"

#include "sim/random.h"

#include <Eigen/Core>

namespace avsplat {

namespace {

using sim::kPi;

// Cameras and rendering.

const Eigen::Vector3d kLookAt(0.25, 0.1, 0.35);
constexpr double kArcRadius = 2.6, kArcHeight = 1.3;
constexpr double kArcFrom = -160.0, kArcTo = -20.0;  // degrees

// The camera at arc position u in [0, 1].
Camera arc_camera(double u, const SimulatorOptions& o) {
    const double phi = (kArcFrom + (kArcTo - kArcFrom) * u) * kPi / 180.0;
    const Eigen::Vector3d eye(kLookAt.x() + kArcRadius * std::cos(phi),
                              kLookAt.y() + kArcRadius * std::sin(phi), kArcHeight);
    return Camera::look_at(eye, kLookAt, Eigen::Vector3d::UnitZ(), o.fov_y, o.width, o.height, 0.01, 100.0);
}

}  // namespace

std::vector<Camera> input_cameras(const SimulatorOptions& o) {
    o.validate();
    std::vector<Camera> cams;
    for (int i = 0; i < o.views; ++i)
        cams.push_back(arc_camera(o.views == 1 ? 0.5 : double(i) / (o.views - 1), o));
    return cams;
}

std::vector<Camera> target_cameras(const SimulatorOptions& o) {
    o.validate();
    std::vector<Camera> cams;
    for (int j = 0; j < o.target_views; ++j) {
        const int g = std::min(o.views - 2, static_cast<int>(std::floor((j + 0.5) * (o.views - 1) / o.target_views)));
        cams.push_back(arc_camera((g + 0.5) / (o.views - 1), o));
    }
    return cams;
}

}  // namespace avsplat
