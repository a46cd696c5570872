#include "avsplat/core/framing.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

double percentile(std::vector<double>& v, double p) {
    // Linear interpolation between order statistics (numpy's default "linear" method).
    const double pos = p / 100.0 * double(v.size() - 1);
    const std::size_t lo = static_cast<std::size_t>(std::floor(pos));
    const std::size_t hi = std::min(lo + 1, v.size() - 1);
    std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(lo), v.end());
    const double a = v[lo];
    if (hi == lo) return a;
    const double b = *std::min_element(v.begin() + std::ptrdiff_t(lo) + 1, v.end());
    return a + (pos - double(lo)) * (b - a);
}

void check(bool ok, const std::string& what) {
    if (!ok) throw std::invalid_argument(what);
}

struct Frame {
    Eigen::Vector3d target;
    double radius;
    Eigen::Vector3d up;         // unit
    Eigen::Vector3d forward0;   // unit, horizontal: azimuth 0 looks along it
    Eigen::Vector3d side;       // unit, up x forward0: azimuth 90 looks along it
};

Frame make_frame(const GaussianCloud& cloud, const FramingOptions& o) {
    check(o.up.allFinite() && o.up.norm() > 0.0, "framing: up must be a finite non-zero vector");
    check(o.fov_y_degrees > 0.0 && o.fov_y_degrees < 180.0, "framing: fov_y_degrees must be in (0, 180)");
    check(o.width > 0 && o.height > 0, "framing: width and height must be positive");
    check(o.elevation_degrees > -90.0 && o.elevation_degrees < 90.0,
          "framing: elevation_degrees must be in (-90, 90)");
    check(std::isfinite(o.azimuth_degrees), "framing: azimuth_degrees must be finite");
    check(!o.radius || (std::isfinite(*o.radius) && *o.radius > 0.0), "framing: radius must be finite and > 0");
    check(!o.target || o.target->allFinite(), "framing: target must be finite");
    Frame f;
    f.up = o.up.normalized();
    const auto [lo, hi] = robust_bounds(cloud, o.low_percentile, o.high_percentile);
    f.target = o.target ? *o.target : Eigen::Vector3d(0.5 * (lo + hi));
    // The sphere around the target that holds the whole robust box.
    double extent = 0.0;
    for (int c = 0; c < 8; ++c) {
        const Eigen::Vector3d corner((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
        extent = std::max(extent, (corner - f.target).norm());
    }
    if (!(extent > 0.0)) extent = std::max(1.0, f.target.norm()) * 1e-3;  // a single point: any small view
    const double half_fov_y = 0.5 * o.fov_y_degrees * M_PI / 180.0;
    const double half_fov_x = std::atan(std::tan(half_fov_y) * double(o.width) / double(o.height));
    f.radius = o.radius ? *o.radius : extent / std::sin(std::min(half_fov_x, half_fov_y));
    // Azimuth 0 looks along +z, or +x when up is along z.
    Eigen::Vector3d ref(0.0, 0.0, 1.0);
    if (std::abs(ref.dot(f.up)) > 0.9) ref = Eigen::Vector3d(1.0, 0.0, 0.0);
    f.forward0 = (ref - ref.dot(f.up) * f.up).normalized();
    f.side = f.up.cross(f.forward0);
    return f;
}

Camera camera_at(const Frame& f, const FramingOptions& o, double azimuth_degrees) {
    const double az = azimuth_degrees * M_PI / 180.0, el = o.elevation_degrees * M_PI / 180.0;
    const Eigen::Vector3d horizontal = std::cos(az) * f.forward0 + std::sin(az) * f.side;
    const Eigen::Vector3d view = std::cos(el) * horizontal - std::sin(el) * f.up;  // eye -> target
    const Eigen::Vector3d eye = f.target - f.radius * view;
    // near well in front of the scene's sphere, far well behind it, whatever the scene's scale.
    const double near = 1e-3 * f.radius;
    return Camera::look_at(eye, f.target, f.up, o.fov_y_degrees, o.width, o.height, near, 1e10 * std::max(1.0, f.radius));
}

}  // namespace

std::pair<Eigen::Vector3d, Eigen::Vector3d> robust_bounds(const GaussianCloud& cloud, double low_percentile,
                                                          double high_percentile) {
    check(low_percentile >= 0.0 && high_percentile <= 100.0 && low_percentile <= high_percentile,
          "robust_bounds: percentiles must satisfy 0 <= low <= high <= 100");
    std::vector<double> axis[3];
    for (auto& a : axis) a.reserve(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
        const auto m = cloud.mean(i);
        if (!m.allFinite()) continue;
        for (int c = 0; c < 3; ++c) axis[c].push_back(double(m[c]));
    }
    check(!axis[0].empty(), "robust_bounds: the cloud has no Gaussian with a finite mean");
    Eigen::Vector3d lo, hi;
    for (int c = 0; c < 3; ++c) {
        lo[c] = percentile(axis[c], low_percentile);
        hi[c] = percentile(axis[c], high_percentile);
    }
    return {lo, hi};
}

Camera default_camera(const GaussianCloud& cloud, const FramingOptions& options) {
    const Frame f = make_frame(cloud, options);
    Camera c = camera_at(f, options, options.azimuth_degrees);
    c.name = "default";
    return c;
}

std::vector<Camera> orbit_cameras(const GaussianCloud& cloud, int n, const FramingOptions& options) {
    check(n >= 1, "orbit_cameras: n must be >= 1");
    const Frame f = make_frame(cloud, options);
    std::vector<Camera> cameras;
    cameras.reserve(std::size_t(n));
    for (int k = 0; k < n; ++k) {
        cameras.push_back(camera_at(f, options, options.azimuth_degrees + 360.0 * k / n));
        char name[32];
        std::snprintf(name, sizeof name, "orbit_%03d", k);
        cameras.back().name = name;
    }
    return cameras;
}

}  // namespace avsplat
