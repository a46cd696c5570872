// Framing: cameras for a scene that came without any, from the scene's robust bounds.
//
// The robust bounds are per-axis percentiles of the means (2nd and 98th by default), so a few
// floaters far from the scene do not push the camera away. The camera looks at the centre of
// that box from a distance at which the box's bounding sphere fits the field of view, so every
// corner of the box projects inside the image.
//
// Up axis: avsplat's world has OpenCV/3DGS axes (x right, y down, z forward); every reader
// converts to them (SPZ's RUB included), and scenes reconstructed by COLMAP and trained by 3DGS
// are y-down. So the default up is -y. Azimuth 0 views the scene along +z (as COLMAP's first
// camera usually does); positive elevation puts the camera above the target (towards up).
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"

#include <Eigen/Core>

#include <optional>
#include <vector>

namespace avsplat {

/// Per-axis percentiles of the finite means: {low corner, high corner}. Percentiles in [0, 100],
/// low <= high; interpolated linearly between order statistics. Throws std::invalid_argument
/// when the cloud has no finite mean or the percentiles are out of range.
std::pair<Eigen::Vector3d, Eigen::Vector3d> robust_bounds(const GaussianCloud& cloud, double low_percentile = 2.0,
                                                          double high_percentile = 98.0);

struct FramingOptions {
    Eigen::Vector3d up{0.0, -1.0, 0.0};  ///< world direction shown up in the images
    double fov_y_degrees = 50.0;         ///< vertical field of view, in (0, 180)
    int width = 1024;                    ///< image size in pixels
    int height = 768;
    double elevation_degrees = 20.0;  ///< angle of the camera above the target's horizontal plane, in (-90, 90)
    double azimuth_degrees = 0.0;     ///< of the first camera, about `up`; 0 looks along +z
    /// Distance from the target; unset: the box's bounding sphere just fits the field of view.
    std::optional<double> radius;
    /// Where the cameras look; unset: the centre of the robust bounds.
    std::optional<Eigen::Vector3d> target;
    double low_percentile = 2.0;  ///< the robust bounds (see robust_bounds)
    double high_percentile = 98.0;
};

/// One camera framing the scene's robust bounds (see the file comment). Throws
/// std::invalid_argument naming the option that is out of range, or when the cloud is empty.
Camera default_camera(const GaussianCloud& cloud, const FramingOptions& options = {});

/// `n` cameras evenly spaced in azimuth around `up` (360 / n degrees apart, counter-clockwise
/// seen from above), at the elevation and distance of default_camera; the first is
/// default_camera. Names are "orbit_000", "orbit_001", ... Throws std::invalid_argument when
/// n < 1 or for the reasons default_camera does.
std::vector<Camera> orbit_cameras(const GaussianCloud& cloud, int n, const FramingOptions& options = {});

}  // namespace avsplat
