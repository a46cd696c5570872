// Simulated predictions and ground truth: ray-cast views of the default scene, with the depth,
// pose and confidence errors of a feed-forward model (see sim/simulator.h for the model).
#include "avsplat/sim/simulator.h"

#include "sim/appearance.h"
#include "sim/footprint.h"
#include "sim/prediction_errors.h"
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
using sim::FootprintKernel;
using sim::footprint_kernel;

Eigen::Vector3d background_of(const SimulatorOptions& o) {
    return Eigen::Vector3d(o.background[0], o.background[1], o.background[2]);
}

// Direction (camera-space z = 1, so t is the camera-space depth) of image point (x, y).
Eigen::Vector3d pixel_direction(const Camera& cam, const Eigen::Matrix3d& c2w_rot, double x, double y) {
    return c2w_rot * Eigen::Vector3d((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0);
}

// The ground-truth render plus the pixel-centre hit points (H x W x 3, double) and the diffuse
// colour (without the view-dependent term; empty when options.specular is 0).
struct View {
    GroundTruthImage image;
    std::vector<Eigen::Vector3d> points;
    std::vector<float> diffuse;
};

View render_view(const Scene& scene, const Camera& cam, const SimulatorOptions& o) {
    const int W = cam.width, H = cam.height, ss = o.supersample;
    const std::size_t np = static_cast<std::size_t>(W) * H;
    const Eigen::Matrix3d R = cam.world_to_camera.block<3, 3>(0, 0).transpose();
    const Eigen::Vector3d origin = cam.position();
    const bool shaded = o.specular > 0.0;

    // The footprint's samples: a grid of ss x ss stratified samples per pixel, pixel (x, y),
    // sample (a, b) at (x + (a + 0.5) / ss, y + (b + 0.5) / ss), over the image and a margin of
    // the footprint's support around it. Each sample is cast once and shared by the pixels
    // whose footprint holds it.
    const FootprintKernel kernel = footprint_kernel(ss, o.footprint_sigma);
    const int M = kernel.margin;
    const int GW = (W + 2 * M) * ss, GH = (H + 2 * M) * ss;
    const std::size_t ns = static_cast<std::size_t>(GW) * GH;
    std::vector<Eigen::Vector3d> sample_color(ns), sample_diffuse(shaded ? ns : 0);
    std::vector<std::uint8_t> sample_hit(ns, 0);
    const Eigen::Vector3d bg(background_of(o));
#pragma omp parallel for schedule(dynamic, 16)
    for (std::int64_t gy = 0; gy < GH; ++gy) {
        const double y = static_cast<double>(gy / ss - M);
        const int b = static_cast<int>(gy % ss);
        for (int gx = 0; gx < GW; ++gx) {
            const double x = static_cast<double>(gx / ss - M);
            const int a = gx % ss;
            const std::size_t g = static_cast<std::size_t>(gy) * GW + gx;
            const Eigen::Vector3d d = pixel_direction(cam, R, x + (a + 0.5) / ss, y + (b + 0.5) / ss);
            const Hit h = scene.cast(origin, d, cam.near, cam.far);
            if (h.object == SceneObject::Background) {
                sample_color[g] = bg;
                if (shaded) sample_diffuse[g] = bg;
                continue;
            }
            const Eigen::Vector3d albedo = scene_color(origin + h.t * d, h.object).cast<double>();
            sample_hit[g] = 1;
            if (shaded) {
                sample_diffuse[g] = albedo;
                const Eigen::Vector3d lit = albedo + o.specular * sim::view_dependent_term(h.object, h.normal, -d.normalized());
                sample_color[g] = lit.cwiseMin(1.0);
            } else {
                sample_color[g] = albedo;
            }
        }
    }

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
    if (shaded) v.diffuse.assign(3 * np, 0.f);
    const int taps = static_cast<int>(kernel.weight.size());
#pragma omp parallel for schedule(dynamic, 64)
    for (std::int64_t ii = 0; ii < static_cast<std::int64_t>(np); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        const int px = static_cast<int>(i % W), py = static_cast<int>(i / W);
        Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum_diffuse = Eigen::Vector3d::Zero();
        double weight = 0.0, hit_weight = 0.0;
        // Samples of the footprint: grid rows py ss .. py ss + taps - 1 (the grid starts M
        // pixels before the image), likewise columns; row-major, as the weights.
        for (int jb = 0; jb < taps; ++jb) {
            const std::size_t row = static_cast<std::size_t>(py * ss + jb) * GW;
            for (int ja = 0; ja < taps; ++ja) {
                const std::size_t g = row + static_cast<std::size_t>(px * ss + ja);
                const double w = kernel.weight[jb] * kernel.weight[ja];
                sum += w * sample_color[g];
                if (shaded) sum_diffuse += w * sample_diffuse[g];
                weight += w;
                if (sample_hit[g]) hit_weight += w;
            }
        }
        for (int c = 0; c < 3; ++c) img.color[3 * i + c] = static_cast<float>(sum[c] / weight);
        if (shaded)
            for (int c = 0; c < 3; ++c) v.diffuse[3 * i + c] = static_cast<float>(sum_diffuse[c] / weight);
        img.alpha[i] = static_cast<float>(hit_weight / weight);
        const Eigen::Vector3d d = pixel_direction(cam, R, px + 0.5, py + 0.5);
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
    if (!(footprint_sigma >= 0.0 && footprint_sigma <= 8.0)) fail("footprint_sigma: must be in [0, 8] pixels");
    if (!(exposure_sigma >= 0.0) || !std::isfinite(exposure_sigma)) fail("exposure_sigma: must be finite and >= 0");
    if (!(white_balance_sigma >= 0.0) || !std::isfinite(white_balance_sigma))
        fail("white_balance_sigma: must be finite and >= 0");
    if (!(specular >= 0.0 && specular <= 1.0)) fail("specular: must be in [0, 1]");
    if (!(mixed_pixel_radius >= 0.0 && mixed_pixel_radius <= 16.0)) fail("mixed_pixel_radius: must be in [0, 16] pixels");
    if (!(attribute_noise >= 0.0) || !std::isfinite(attribute_noise)) fail("attribute_noise: must be finite and >= 0");
    if (confidence_rho && !(*confidence_rho >= -1.0 && *confidence_rho <= 1.0))
        fail("confidence_rho: must be in [-1, 1]");
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(background[c])) fail("background: must be finite");
}

GroundTruthImage ground_truth(const Camera& camera, const SimulatorOptions& o) {
    camera.validate();
    o.validate();
    const Scene scene;
    return render_view(scene, camera, o).image;
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
    P.uncertainty.assign(total, 0.f);
    P.view_gains.assign(3 * static_cast<std::size_t>(S), 1.f);
    // Per pixel, for the head features: the true depth and the true diffuse colour.
    std::vector<float> depth(total, 0.f), reference(3 * total, 0.f);

    const Scene scene;
    const double rot_sigma = o.pose_noise_rot_deg * kPi / 180.0 / std::sqrt(3.0);
    const double trans_sigma = o.pose_noise_trans / std::sqrt(3.0);
    for (int s = 0; s < S; ++s) {
        const Camera& cam = P.true_cameras[s];
        const View v = render_view(scene, cam, o);
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
        // The colours the model predicts: the image, mixed at depth edges, through the view's gains.
        std::vector<float> color = img.color;
        sim::mix_pixels(color, img.depth, cam, o.mixed_pixel_radius);
        const std::array<double, 3> gain = sim::view_gains(o.seed, s, o.exposure_sigma, o.white_balance_sigma);
        for (int c = 0; c < 3; ++c) P.view_gains[3 * s + c] = static_cast<float>(gain[c]);
        if (o.exposure_sigma > 0.0 || o.white_balance_sigma > 0.0)
            for (std::size_t i = 0; i < per_view; ++i)
                if (img.depth[i] > 0.f)
                    for (int c = 0; c < 3; ++c)
                        color[3 * i + c] = static_cast<float>(std::min(1.0, gain[c] * color[3 * i + c]));
        const std::vector<float>& diffuse = v.diffuse.empty() ? img.color : v.diffuse;
        std::copy(img.depth.begin(), img.depth.end(), depth.begin() + s * per_view);
        std::copy(diffuse.begin(), diffuse.end(), reference.begin() + 3 * s * per_view);
        std::vector<float> cos(per_view, 0.f);
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
                for (int c = 0; c < 3; ++c) P.colors[3 * k + c] = color[3 * i + c];
                if (img.object_id[i] == static_cast<std::int32_t>(SceneObject::Background)) continue;

                const double d = true_depth(x, y);
                const Eigen::Vector3d p_true = v.points[i];
                const Eigen::Vector3d nrm(img.normals[3 * i], img.normals[3 * i + 1], img.normals[3 * i + 2]);
                const double cos_theta = std::abs(nrm.dot((p_true - C).normalized()));
                cos[i] = static_cast<float>(cos_theta);
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
        const std::vector<float> u = sim::uncertainty(img.depth, cos, diffuse, cam);
        std::copy(u.begin(), u.end(), P.uncertainty.begin() + s * per_view);
    }
    sim::head_features(P, o, depth, reference);
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

GaussianCloud Predictions::decoded_gaussians() const {
    const int C = feature_layout.channels();
    std::vector<float> pos, feat, conf;
    for (std::size_t k = 0; k < valid.size(); ++k) {
        if (!valid[k]) continue;
        pos.insert(pos.end(), &points[3 * k], &points[3 * k] + 3);
        feat.insert(feat.end(), &features[k * C], &features[k * C] + C);
        conf.push_back(confidence[k]);
    }
    return decode_gaussians(pos.data(), conf.size(), feat.data(), C, feature_layout, conf.data());
}

}  // namespace avsplat
