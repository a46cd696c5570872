#include "avsplat/core/camera.h"

#include <Eigen/Geometry>

#include <cmath>
#include <stdexcept>

namespace avsplat {

Camera::Camera(double fx_, double fy_, double cx_, double cy_, int width_, int height_,
               const Eigen::Matrix4d& w2c, double near_, double far_)
    : fx(fx_), fy(fy_), cx(cx_), cy(cy_), width(width_), height(height_),
      world_to_camera(w2c), near(near_), far(far_) {}

Camera Camera::look_at(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                       const Eigen::Vector3d& up, double fov_y_degrees, int width, int height,
                       double near, double far) {
    const Eigen::Vector3d forward = target - eye;
    if (!(forward.norm() > 0.0))
        throw std::invalid_argument("Camera::look_at: eye and target coincide");
    const Eigen::Vector3d z = forward.normalized();
    const Eigen::Vector3d right = z.cross(up);
    if (!(right.norm() > 1e-12 * up.norm()) || up.norm() == 0.0)
        throw std::invalid_argument("Camera::look_at: up is zero or parallel to the view direction");
    const Eigen::Vector3d x = right.normalized();
    const Eigen::Vector3d y = z.cross(x);  // points down in the image
    if (!(fov_y_degrees > 0.0 && fov_y_degrees < 180.0))
        throw std::invalid_argument("Camera::look_at: fov_y_degrees must be in (0, 180)");
    if (width <= 0 || height <= 0)
        throw std::invalid_argument("Camera::look_at: width and height must be positive");
    Eigen::Matrix4d w2c = Eigen::Matrix4d::Identity();
    w2c.block<1, 3>(0, 0) = x.transpose();
    w2c.block<1, 3>(1, 0) = y.transpose();
    w2c.block<1, 3>(2, 0) = z.transpose();
    w2c.block<3, 1>(0, 3) = -w2c.block<3, 3>(0, 0) * eye;
    const double f = 0.5 * height / std::tan(0.5 * fov_y_degrees * M_PI / 180.0);
    return Camera(f, f, 0.5 * width, 0.5 * height, width, height, w2c, near, far);
}

Eigen::Vector3d Camera::position() const {
    const Eigen::Matrix3d R = world_to_camera.block<3, 3>(0, 0);
    return -R.transpose() * world_to_camera.block<3, 1>(0, 3);
}

Eigen::Matrix4d Camera::camera_to_world() const {
    Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
    const Eigen::Matrix3d R = world_to_camera.block<3, 3>(0, 0);
    c2w.block<3, 3>(0, 0) = R.transpose();
    c2w.block<3, 1>(0, 3) = -R.transpose() * world_to_camera.block<3, 1>(0, 3);
    return c2w;
}

void Camera::validate() const {
    auto fail = [](const std::string& what) { throw std::invalid_argument("Camera." + what); };
    if (!std::isfinite(fx) || !(fx > 0.0)) fail("fx: must be finite and > 0");
    if (!std::isfinite(fy) || !(fy > 0.0)) fail("fy: must be finite and > 0");
    if (!std::isfinite(cx)) fail("cx: must be finite");
    if (!std::isfinite(cy)) fail("cy: must be finite");
    if (width <= 0) fail("width: must be > 0");
    if (height <= 0) fail("height: must be > 0");
    if (!std::isfinite(near) || !(near > 0.0)) fail("near: must be finite and > 0");
    if (!(far > near)) fail("far: must be > near");
    if (!world_to_camera.allFinite()) fail("world_to_camera: NaN or Inf");
    const Eigen::Matrix3d R = world_to_camera.block<3, 3>(0, 0);
    if ((R * R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-4 ||
        R.determinant() < 0.0)
        fail("world_to_camera: the rotation block is not a rotation (orthonormal, det +1)");
    if (world_to_camera.row(3) != Eigen::RowVector4d(0, 0, 0, 1))
        fail("world_to_camera: the last row must be (0, 0, 0, 1)");
}

}  // namespace avsplat
