// Camera: a pinhole camera with OpenCV axes (x right, y down, z forward).
//
// A world point X maps to camera coordinates Xc = world_to_camera * [X; 1] and to pixel
// coordinates u = fx * Xc.x / Xc.z + cx, v = fy * Xc.y / Xc.z + cy. Pixel (i, j) (column i,
// row j) has its centre at (i + 0.5, j + 0.5), as in gsplat. Points with Xc.z outside
// [near, far] are not rendered.
#pragma once

#include <Eigen/Core>

#include <string>

namespace avsplat {

struct Camera {
    double fx = 1.0;
    double fy = 1.0;
    double cx = 0.0;
    double cy = 0.0;
    int width = 0;
    int height = 0;
    Eigen::Matrix4d world_to_camera = Eigen::Matrix4d::Identity();
    double near = 0.01;
    double far = 1e10;
    /// Optional label (an image name from a cameras file); not used by the maths.
    std::string name;

    Camera() = default;
    Camera(double fx, double fy, double cx, double cy, int width, int height,
           const Eigen::Matrix4d& world_to_camera = Eigen::Matrix4d::Identity(),
           double near = 0.01, double far = 1e10);

    /// A camera at `eye` looking at `target`, with `up` pointing up in the image (towards -y),
    /// vertical field of view `fov_y_degrees`, principal point at the image centre and square
    /// pixels. Throws std::invalid_argument when eye == target or up is parallel to the view.
    static Camera look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                          const Eigen::Vector3d& up, double fov_y_degrees, int width, int height,
                          double near = 0.01, double far = 1e10);

    /// Camera centre in world coordinates.
    Eigen::Vector3d position() const;
    /// Inverse of world_to_camera (rigid inverse).
    Eigen::Matrix4d camera_to_world() const;

    /// Throws std::invalid_argument naming the field when the camera is unusable: non-finite
    /// values, fx or fy <= 0, width or height <= 0, 0 < near < far violated, or a
    /// world_to_camera whose rotation block is not orthonormal (tolerance 1e-4) or whose last
    /// row is not (0, 0, 0, 1).
    void validate() const;
};

}  // namespace avsplat
