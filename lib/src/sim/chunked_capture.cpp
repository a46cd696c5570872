// Simulated chunked captures (sim/chunked_capture.h).
#include "avsplat/sim/chunked_capture.h"

#include "sim/random.h"

#include <Eigen/Geometry>

#include <cmath>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

using sim::kPi;

template <class T>
void copy_views(const std::vector<T>& from, std::vector<T>& to, std::size_t per_view, int first, int count) {
    if (from.empty()) return;
    to.assign(from.begin() + first * per_view, from.begin() + (first + count) * per_view);
}

// A camera in a frame x' = s (R x + t): the same image, camera coordinates scaled by s.
Camera moved_camera(Camera cam, const Similarity& T) {
    const Eigen::Matrix3d A = cam.world_to_camera.block<3, 3>(0, 0);
    const Eigen::Vector3d b = cam.world_to_camera.block<3, 1>(0, 3);
    const Similarity inv = T.inverse();  // x = inv(x')
    // camera coordinates s (A x + b) = A R^T x' + s b - A R^T t
    Eigen::Matrix4d w2c = Eigen::Matrix4d::Identity();
    w2c.block<3, 3>(0, 0) = A * inv.rotation;
    w2c.block<3, 1>(0, 3) = T.scale * (A * inv.translation + b);
    cam.world_to_camera = w2c;
    cam.near *= T.scale;
    cam.far *= T.scale;
    return cam;
}

}  // namespace

void ChunkedCaptureOptions::validate(int frames) const {
    if (window < 2 || window > frames)
        throw std::invalid_argument("window must be in 2.." + std::to_string(frames) + " (the frame count), got " +
                                    std::to_string(window));
    if (overlap < 1 || overlap >= window)
        throw std::invalid_argument("overlap must be in 1.." + std::to_string(window - 1) + ", got " +
                                    std::to_string(overlap));
    if (!(std::isfinite(min_scale) && std::isfinite(max_scale) && min_scale > 0.0 && min_scale <= max_scale))
        throw std::invalid_argument("min_scale and max_scale must be finite with 0 < min_scale <= max_scale");
}

PredictionChunk CaptureChunk::prediction_chunk(const std::string& name) const {
    PredictionChunk c;
    c.name = name;
    c.views = predictions.views;
    c.height = predictions.height;
    c.width = predictions.width;
    c.frame_ids = frame_ids;
    c.points = predictions.points;
    c.valid = predictions.valid;
    c.confidence = predictions.confidence;
    c.confidence_mapping = ConfidenceMapping::Logit;
    c.gaussians = predictions.gaussians();
    return c;
}

ChunkedCapture simulate_chunked_capture(const SimulatorOptions& o, const ChunkedCaptureOptions& k) {
    o.validate();
    k.validate(o.views);
    ChunkedCapture out;
    out.trajectory = simulate_predictions(o);
    const Predictions& P = out.trajectory;
    const int N = o.views, H = o.height, W = o.width;
    const std::size_t per_view = std::size_t(H) * W;
    std::vector<int> starts;
    for (int s = 0;; s += k.window - k.overlap) {
        if (s + k.window >= N) {
            starts.push_back(N - k.window);
            break;
        }
        starts.push_back(s);
    }
    const double rot_sigma = o.pose_noise_rot_deg * kPi / 180.0 / std::sqrt(3.0);
    const double trans_sigma = o.pose_noise_trans / std::sqrt(3.0);
    for (std::size_t w = 0; w < starts.size(); ++w) {
        const int first = starts[w], S = k.window;
        CaptureChunk chunk;
        Predictions& C = chunk.predictions;
        C.views = S;
        C.height = H;
        C.width = W;
        copy_views(P.points, C.points, 3 * per_view, first, S);
        copy_views(P.colors, C.colors, 3 * per_view, first, S);
        copy_views(P.confidence, C.confidence, per_view, first, S);
        copy_views(P.true_error, C.true_error, per_view, first, S);
        copy_views(P.true_points, C.true_points, 3 * per_view, first, S);
        copy_views(P.normals, C.normals, 3 * per_view, first, S);
        copy_views(P.valid, C.valid, per_view, first, S);
        copy_views(P.object_id, C.object_id, per_view, first, S);
        copy_views(P.uncertainty, C.uncertainty, per_view, first, S);
        copy_views(P.appearance_error, C.appearance_error, per_view, first, S);
        copy_views(P.view_gains, C.view_gains, 3, first, S);
        C.cameras.assign(P.cameras.begin() + first, P.cameras.begin() + first + S);
        C.true_cameras.assign(P.true_cameras.begin() + first, P.true_cameras.begin() + first + S);
        C.target_cameras = P.target_cameras;
        C.confidence_spearman = P.confidence_spearman;
        for (int s = 0; s < S; ++s) chunk.frame_ids.push_back(first + s);

        // This window's own prediction errors.
        for (int s = 0; s < S; ++s) {
            sim::Rng rng(sim::splitmix64(k.seed ^ sim::splitmix64(0xC4u + 1000003ull * w + std::uint64_t(first + s))));
            Eigen::Vector3d omega, t_err;
            for (int c = 0; c < 3; ++c) omega[c] = rot_sigma * rng.normal();
            for (int c = 0; c < 3; ++c) t_err[c] = trans_sigma * rng.normal();
            const Eigen::Matrix3d R_err = omega.norm() > 0.0
                ? Eigen::AngleAxisd(omega.norm(), omega.normalized()).toRotationMatrix()
                : Eigen::Matrix3d::Identity();
            Camera& cam = C.cameras[s];
            const Eigen::Vector3d centre = cam.position();
            Eigen::Matrix4d motion_inv = Eigen::Matrix4d::Identity();
            motion_inv.block<3, 3>(0, 0) = R_err.transpose();
            motion_inv.block<3, 1>(0, 3) = centre - R_err.transpose() * (centre + t_err);
            cam.world_to_camera = cam.world_to_camera * motion_inv;
            for (std::size_t p = 0; p < per_view; ++p) {
                const double n_depth = rng.normal();
                const std::size_t i = s * per_view + p;
                if (!C.valid[i]) continue;
                const double factor = std::max(0.1, 1.0 + o.depth_noise * n_depth);
                const Eigen::Vector3d x(C.points[3 * i], C.points[3 * i + 1], C.points[3 * i + 2]);
                const Eigen::Vector3d y = centre + t_err + R_err * (factor * (x - centre));
                const Eigen::Vector3d nrm = R_err * Eigen::Vector3d(C.normals[3 * i], C.normals[3 * i + 1], C.normals[3 * i + 2]);
                const Eigen::Vector3d truth(C.true_points[3 * i], C.true_points[3 * i + 1], C.true_points[3 * i + 2]);
                for (int c = 0; c < 3; ++c) {
                    C.points[3 * i + c] = static_cast<float>(y[c]);
                    C.normals[3 * i + c] = static_cast<float>(nrm[c]);
                }
                C.true_error[i] = static_cast<float>((y - truth).norm());
            }
        }

        // The window's frame: its first true camera's coordinates, at a random scale.
        sim::Rng scale_rng(sim::splitmix64(k.seed ^ sim::splitmix64(0x5CA1Eull + w)));
        const double scale = std::exp(std::log(k.min_scale) + scale_rng.uniform() * std::log(k.max_scale / k.min_scale));
        Similarity chunk_from_world;
        chunk_from_world.rotation = C.true_cameras[0].world_to_camera.block<3, 3>(0, 0);
        chunk_from_world.translation = scale * C.true_cameras[0].world_to_camera.block<3, 1>(0, 3);
        chunk_from_world.scale = scale;
        chunk.world_from_chunk = chunk_from_world.inverse();
        for (std::size_t i = 0; i < C.valid.size(); ++i) {
            if (!C.valid[i]) continue;
            const Eigen::Vector3d x(C.points[3 * i], C.points[3 * i + 1], C.points[3 * i + 2]);
            const Eigen::Vector3d t(C.true_points[3 * i], C.true_points[3 * i + 1], C.true_points[3 * i + 2]);
            const Eigen::Vector3d nrm(C.normals[3 * i], C.normals[3 * i + 1], C.normals[3 * i + 2]);
            const Eigen::Vector3d x2 = chunk_from_world.apply(x), t2 = chunk_from_world.apply(t);
            const Eigen::Vector3d n2 = chunk_from_world.rotation * nrm;
            for (int c = 0; c < 3; ++c) {
                C.points[3 * i + c] = static_cast<float>(x2[c]);
                C.true_points[3 * i + c] = static_cast<float>(t2[c]);
                C.normals[3 * i + c] = static_cast<float>(n2[c]);
            }
            C.true_error[i] = static_cast<float>(scale * C.true_error[i]);
        }
        for (Camera& cam : C.cameras) cam = moved_camera(cam, chunk_from_world);
        for (Camera& cam : C.true_cameras) cam = moved_camera(cam, chunk_from_world);
        for (Camera& cam : C.target_cameras) cam = moved_camera(cam, chunk_from_world);
        out.chunks.push_back(std::move(chunk));
    }
    return out;
}

}  // namespace avsplat
