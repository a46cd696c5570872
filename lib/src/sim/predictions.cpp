// Simulated predictions and ground truth: ray-cast views of the default scene, with the depth,
// pose and confidence errors of a feed-forward model (see sim/simulator.h for the model).
#include "avsplat/sim/simulator.h"

#include "sim/random.h"
#include "sim/raycast.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

using sim::Hit;
using sim::kPi;
using sim::Rng;
using sim::Scene;
using sim::splitmix64;
using sim::to_unit;

// Direction (camera-space z = 1, so t is the camera-space depth) of image point (x, y).
Eigen::Vector3d pixel_direction(const Camera& cam, const Eigen::Matrix3d& c2w_rot, double x, double y) {
    return c2w_rot * Eigen::Vector3d((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0);
}

// The ground-truth render plus the pixel-centre hit points (H x W x 3, double).
struct View {
    GroundTruthImage image;
    std::vector<Eigen::Vector3d> points;
};

View render_view(const Scene& scene, const Camera& cam, int ss, const std::array<float, 3>& background) {
    const int W = cam.width, H = cam.height;
    const std::size_t np = static_cast<std::size_t>(W) * H;
    const Eigen::Matrix3d R = cam.world_to_camera.block<3, 3>(0, 0).transpose();
    const Eigen::Vector3d origin = cam.position();

    // Stratified samples: pixel (x, y), sample (a, b) at (x + (a + 0.5) / ss, y + (b + 0.5) / ss).
    const std::size_t per_pixel = static_cast<std::size_t>(ss) * ss;
    View v;
    GroundTruthImage& img = v.image;
    img.width = W;
    img.height = H;
    img.color.assign(3 * np, 0.f);
    img.alpha.assign(np, 0.f);
    img.depth.assign(np, 0.f);
    img.normals.assign(3 * np, 0.f);
    img.object_id.assign(np, static_cast<std::int32_t>(SceneObject::Background));
    v.points.assign(np, Eigen::Vector3d::Zero());
    const Eigen::Vector3d bg(background[0], background[1], background[2]);
#pragma omp parallel for schedule(dynamic, 64)
    for (std::int64_t ii = 0; ii < static_cast<std::int64_t>(np); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        const double x = static_cast<double>(i % W), y = static_cast<double>(i / W);
        Eigen::Vector3d sum = Eigen::Vector3d::Zero();
        int hits = 0;
        for (int b = 0; b < ss; ++b) {
            for (int a = 0; a < ss; ++a) {
                const Eigen::Vector3d d = pixel_direction(cam, R, x + (a + 0.5) / ss, y + (b + 0.5) / ss);
                const Hit h = scene.cast(origin, d, cam.near, cam.far);
                if (h.object == SceneObject::Background) {
                    sum += bg;
                } else {
                    sum += scene_color(origin + h.t * d, h.object).cast<double>();
                    ++hits;
                }
            }
        }
        for (int c = 0; c < 3; ++c) img.color[3 * i + c] = static_cast<float>(sum[c] / per_pixel);
        img.alpha[i] = static_cast<float>(double(hits) / per_pixel);
        const Eigen::Vector3d d = pixel_direction(cam, R, x + 0.5, y + 0.5);
        const Hit h = scene.cast(origin, d, cam.near, cam.far);
        if (h.object == SceneObject::Background) continue;
        img.depth[i] = static_cast<float>(h.t);
        img.object_id[i] = static_cast<std::int32_t>(h.object);
        for (int c = 0; c < 3; ++c) img.normals[3 * i + c] = static_cast<float>(h.normal[c]);
        v.points[i] = origin + h.t * d;
    }
    return v;
}

// Random numbers with portable transforms (std::*_distribution differ between libraries).

}  // namespace

void SimulatorOptions::validate() const {
    auto fail = [](const std::string& what) { throw std::invalid_argument("SimulatorOptions." + what); };
    if (views < 1) fail("views: must be >= 1");
    if (width < 1) fail("width: must be >= 1");
    if (height < 1) fail("height: must be >= 1");
    if (!(fov_y > 0.0 && fov_y < 180.0)) fail("fov_y: must be in (0, 180) degrees");
    if (target_views < 0 || target_views > views - 1)
        fail("target_views: must be in [0, views - 1] (each target sits in its own gap between input "
             "views); got " + std::to_string(target_views) + " with views = " + std::to_string(views));
    if (!(pose_noise_rot_deg >= 0.0) || !std::isfinite(pose_noise_rot_deg)) fail("pose_noise_rot_deg: must be finite and >= 0");
    if (!(pose_noise_trans >= 0.0) || !std::isfinite(pose_noise_trans)) fail("pose_noise_trans: must be finite and >= 0");
    if (!(depth_noise >= 0.0) || !std::isfinite(depth_noise)) fail("depth_noise: must be finite and >= 0");
    if (!(confidence_noise >= 0.0) || !std::isfinite(confidence_noise)) fail("confidence_noise: must be finite and >= 0");
    if (supersample < 1 || supersample > 16) fail("supersample: must be in 1..16");
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(background[c])) fail("background: must be finite");
}

GroundTruthImage ground_truth(const Camera& camera, const SimulatorOptions& o) {
    camera.validate();
    o.validate();
    const Scene scene;
    return render_view(scene, camera, o.supersample, o.background).image;
}

Predictions simulate_predictions(const SimulatorOptions& o) {
    o.validate();
    const int S = o.views, H = o.height, W = o.width;
    const std::size_t per_view = static_cast<std::size_t>(H) * W;
    const std::size_t total = per_view * S;
    Predictions P;
    P.views = S;
    P.height = H;
    P.width = W;
    P.points.assign(3 * total, 0.f);
    P.colors.resize(3 * total);
    P.confidence.assign(total, 0.f);
    P.true_error.assign(total, 0.f);
    P.true_points.assign(3 * total, 0.f);
    P.normals.assign(3 * total, 0.f);
    P.valid.assign(total, 0);
    P.object_id.assign(total, static_cast<std::int32_t>(SceneObject::Background));
    P.true_cameras = input_cameras(o);
    P.target_cameras = target_cameras(o);

    const Scene scene;
    const double rot_sigma = o.pose_noise_rot_deg * kPi / 180.0 / std::sqrt(3.0);
    const double trans_sigma = o.pose_noise_trans / std::sqrt(3.0);
    for (int s = 0; s < S; ++s) {
        const Camera& cam = P.true_cameras[s];
        const View v = render_view(scene, cam, o.supersample, o.background);
        Rng rng(splitmix64(o.seed ^ splitmix64(0x5EEDull + static_cast<std::uint64_t>(s))));

        // Misregistration: a rigid motion about the camera centre C,
        // x -> R_err (x - C) + C + t_err, applied to the camera and to its point map.
        Eigen::Vector3d omega, t_err;
        for (int c = 0; c < 3; ++c) omega[c] = rot_sigma * rng.normal();
        for (int c = 0; c < 3; ++c) t_err[c] = trans_sigma * rng.normal();
        const Eigen::Matrix3d R_err = omega.norm() > 0.0
            ? Eigen::AngleAxisd(omega.norm(), omega.normalized()).toRotationMatrix()
            : Eigen::Matrix3d::Identity();
        const Eigen::Vector3d C = cam.position();
        Eigen::Matrix4d motion_inv = Eigen::Matrix4d::Identity();  // y -> R^T (y - C - t) + C
        motion_inv.block<3, 3>(0, 0) = R_err.transpose();
        motion_inv.block<3, 1>(0, 3) = C - R_err.transpose() * (C + t_err);
        Camera predicted = cam;
        predicted.world_to_camera = cam.world_to_camera * motion_inv;
        P.cameras.push_back(predicted);

        const GroundTruthImage& img = v.image;
        auto true_depth = [&](int x, int y) { return static_cast<double>(img.depth[std::size_t(y) * W + x]); };
        for (int y = 0; y < H; ++y) {
            for (int x = 0; x < W; ++x) {
                const std::size_t i = std::size_t(y) * W + x;
                const std::size_t k = s * per_view + i;
                // Every pixel draws the same numbers, so one pixel's validity never shifts the
                // stream of the others.
                const double n_depth = rng.normal();
                const double u_fly = rng.uniform();
                const double n_conf = rng.normal();
                for (int c = 0; c < 3; ++c) P.colors[3 * k + c] = img.color[3 * i + c];
                if (img.object_id[i] == static_cast<std::int32_t>(SceneObject::Background)) continue;

                const double d = true_depth(x, y);
                const Eigen::Vector3d p_true = v.points[i];
                const Eigen::Vector3d nrm(img.normals[3 * i], img.normals[3 * i + 1], img.normals[3 * i + 2]);
                const double cos_theta = std::abs(nrm.dot((p_true - C).normalized()));
                double factor = 1.0 + o.depth_noise * (1.0 + 2.0 * (1.0 - cos_theta)) * n_depth;
                if (o.flying_pixels) {
                    // A depth step no surface makes between neighbouring pixels unless it is
                    // slanted by more than about 83 degrees to the ray: a discontinuity.
                    const double step = 8.0 * d / std::sqrt(cam.fx * cam.fy);
                    double best = 0.0, d_n = d;
                    const int nx[4] = {x - 1, x + 1, x, x}, ny[4] = {y, y, y - 1, y + 1};
                    for (int q = 0; q < 4; ++q) {
                        if (nx[q] < 0 || nx[q] >= W || ny[q] < 0 || ny[q] >= H) continue;
                        const double dq = true_depth(nx[q], ny[q]);
                        if (dq <= 0.0) continue;  // background
                        if (std::abs(dq - d) > step && std::abs(dq - d) > best) {
                            best = std::abs(dq - d);
                            d_n = dq;
                        }
                    }
                    factor *= (d + 0.5 * u_fly * (d_n - d)) / d;
                }
                factor = std::max(factor, 0.1);
                const Eigen::Vector3d p_pred = C + t_err + R_err * (factor * (p_true - C));
                const double err = (p_pred - p_true).norm();
                const Eigen::Vector3d n_pred = R_err * nrm;
                for (int c = 0; c < 3; ++c) {
                    P.points[3 * k + c] = static_cast<float>(p_pred[c]);
                    P.true_points[3 * k + c] = static_cast<float>(p_true[c]);
                    P.normals[3 * k + c] = static_cast<float>(n_pred[c]);
                }
                P.true_error[k] = static_cast<float>(err);
                P.confidence[k] = static_cast<float>(std::log(0.01 * d / std::max(err, 1e-6 * d)) +
                                                     o.confidence_noise * n_conf);
                P.valid[k] = 1;
                P.object_id[k] = img.object_id[i];
            }
        }
    }
    return P;
}

PointMaps Predictions::point_maps() const {
    PointMaps m;
    m.views = views;
    m.height = height;
    m.width = width;
    m.points = points.data();
    m.colors = colors.data();
    m.confidence = confidence.data();
    m.normals = normals.data();
    m.valid = valid.data();
    return m;
}

GaussianCloud Predictions::gaussians(const PointMapOptions& options) const {
    return gaussians_from_point_maps(point_maps(), cameras, options);
}

}  // namespace avsplat
