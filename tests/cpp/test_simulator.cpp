// Tests of the simulator (sim/simulator.h) that need no Open3D: they run in avsplat_tests, and so
// under the sanitizers too. The checks against Open3D's distance queries and mesh reader are in
// test_simulator_open3d.cpp.
#include "avsplat/sim/simulator.h"

#include "simulator_test_helpers.h"

#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <numeric>

using avsplat::Camera;
using avsplat::Predictions;
using avsplat::SceneObject;
using avsplat::SimulatorOptions;
using namespace sim_test;

namespace {

// Spearman rank correlation (average ranks for ties).
double spearman(const std::vector<double>& a, const std::vector<double>& b) {
    auto ranks = [](const std::vector<double>& v) {
        std::vector<std::size_t> idx(v.size());
        std::iota(idx.begin(), idx.end(), 0);
        std::sort(idx.begin(), idx.end(), [&](std::size_t i, std::size_t j) { return v[i] < v[j]; });
        std::vector<double> r(v.size());
        for (std::size_t s = 0; s < idx.size();) {
            std::size_t e = s;
            while (e + 1 < idx.size() && v[idx[e + 1]] == v[idx[s]]) ++e;
            for (std::size_t k = s; k <= e; ++k) r[idx[k]] = 0.5 * (s + e);
            s = e + 1;
        }
        return r;
    };
    const std::vector<double> ra = ranks(a), rb = ranks(b);
    const double ma = std::accumulate(ra.begin(), ra.end(), 0.0) / ra.size();
    const double mb = std::accumulate(rb.begin(), rb.end(), 0.0) / rb.size();
    double sab = 0, saa = 0, sbb = 0;
    for (std::size_t i = 0; i < ra.size(); ++i) {
        sab += (ra[i] - ma) * (rb[i] - mb);
        saa += (ra[i] - ma) * (ra[i] - ma);
        sbb += (rb[i] - mb) * (rb[i] - mb);
    }
    return sab / std::sqrt(saa * sbb);
}

}  // namespace

TEST_CASE("simulate_predictions is deterministic for a seed and any thread count", "[simulator]") {
    const SimulatorOptions o = small();
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const Predictions a = avsplat::simulate_predictions(o);
    omp_set_num_threads(2);
    const Predictions b = avsplat::simulate_predictions(o);
    omp_set_num_threads(threads);
    CHECK(a.points == b.points);
    CHECK(a.colors == b.colors);
    CHECK(a.confidence == b.confidence);
    CHECK(a.true_error == b.true_error);
    CHECK(a.normals == b.normals);
    CHECK(a.valid == b.valid);
    for (std::size_t s = 0; s < a.cameras.size(); ++s) CHECK(a.cameras[s].world_to_camera == b.cameras[s].world_to_camera);
    SimulatorOptions other = o;
    other.seed = 1;
    const Predictions c = avsplat::simulate_predictions(other);
    CHECK(c.valid == a.valid);  // the geometry does not depend on the seed...
    CHECK(c.points != a.points);  // ...the noise does
    CHECK(c.confidence != a.confidence);
}

TEST_CASE("a ray through the sphere centre hits at the expected depth", "[simulator]") {
    // An odd image size puts the centre pixel's ray on the optical axis.
    const Eigen::Vector3d eye(scene::kSphereCenter[0], -2.0, scene::kSphereCenter[2]);
    const Camera cam = Camera::look_at(eye, kCenter, Eigen::Vector3d::UnitZ(), 30.0, 33, 33);
    SimulatorOptions o;
    o.supersample = 1;
    const auto gt = avsplat::ground_truth(cam, o);
    const std::size_t c = 16 * 33 + 16;
    CHECK(gt.object_id[c] == static_cast<int>(SceneObject::Sphere));
    CHECK(gt.depth[c] == Approx((kCenter - eye).norm() - scene::kSphereRadius).epsilon(1e-6));
    CHECK(at(gt.normals, c).isApprox(Eigen::Vector3d(0, -1, 0), 1e-6));
    CHECK(gt.alpha[c] == 1.f);
}

TEST_CASE("misregistration moves each view's point map rigidly with its predicted camera", "[simulator]") {
    SimulatorOptions o = noise_free(small(3, 32, 24));
    o.pose_noise_rot_deg = 1.0;
    o.pose_noise_trans = 0.05;
    const Predictions p = avsplat::simulate_predictions(o);
    const std::size_t per_view = 32 * 24;
    for (int s = 0; s < 3; ++s) {
        // The predicted camera sees the predicted points exactly where the true camera sees the
        // true ones: p_pred = c2w_pred * w2c_true * p_true.
        const Eigen::Matrix4d M = p.cameras[s].camera_to_world() * p.true_cameras[s].world_to_camera;
        double moved = 0.0;
        for (std::size_t i = s * per_view; i < (s + 1) * per_view; ++i) {
            if (!p.valid[i]) continue;
            const Eigen::Vector3d expected = (M * at(p.true_points, i).homogeneous()).head<3>();
            REQUIRE((at(p.points, i) - expected).norm() < 1e-5);
            moved = std::max(moved, double(p.true_error[i]));
        }
        CHECK(moved > 1e-3);
        CHECK((p.cameras[s].position() - p.true_cameras[s].position()).norm() > 0.0);
        CHECK_NOTHROW(p.cameras[s].validate());
    }
}

TEST_CASE("flying pixels appear only at depth discontinuities", "[simulator]") {
    SimulatorOptions o = noise_free(small(2, 64, 48));
    o.flying_pixels = true;
    const Predictions p = avsplat::simulate_predictions(o);
    const int W = 64, H = 48;
    std::size_t flying = 0;
    for (int s = 0; s < 2; ++s) {
        const Camera& cam = p.true_cameras[s];
        auto depth = [&](int x, int y) {
            const std::size_t i = std::size_t(s) * W * H + std::size_t(y) * W + x;
            return p.valid[i] ? (cam.world_to_camera * at(p.true_points, i).homogeneous()).z() : 0.0;
        };
        for (int y = 0; y < H; ++y)
            for (int x = 0; x < W; ++x) {
                const std::size_t i = std::size_t(s) * W * H + std::size_t(y) * W + x;
                if (!p.valid[i] || p.true_error[i] < 1e-5f) continue;
                ++flying;
                const double d = depth(x, y);
                double step = 0.0;
                if (x > 0) step = std::max(step, depth(x - 1, y) > 0 ? std::abs(depth(x - 1, y) - d) : 0.0);
                if (x + 1 < W) step = std::max(step, depth(x + 1, y) > 0 ? std::abs(depth(x + 1, y) - d) : 0.0);
                if (y > 0) step = std::max(step, depth(x, y - 1) > 0 ? std::abs(depth(x, y - 1) - d) : 0.0);
                if (y + 1 < H) step = std::max(step, depth(x, y + 1) > 0 ? std::abs(depth(x, y + 1) - d) : 0.0);
                REQUIRE(step > 8.0 * d / cam.fx * 0.999);
                // Moved along the ray by at most half the step in depth (z), i.e. by
                // 0.5 step |ray| for the ray whose z component is 1.
                REQUIRE(p.true_error[i] <= 0.5 * step * pixel_ray(cam, x + 0.5, y + 0.5).norm() * 1.0001);
            }
    }
    CHECK(flying > 20);
}

TEST_CASE("the confidence correlates with the true error", "[simulator]") {
    const Predictions p = avsplat::simulate_predictions(small(4, 64, 48));
    std::vector<double> conf, neg_err;
    for (std::size_t i = 0; i < p.valid.size(); ++i)
        if (p.valid[i]) {
            conf.push_back(p.confidence[i]);
            neg_err.push_back(-p.true_error[i]);
        }
    const double rho = spearman(conf, neg_err);
    CHECK(rho > 0.3);
    CHECK(rho < 0.99);  // correlated, not a function of the error
    // Without confidence noise the confidence is a decreasing function of the relative error.
    SimulatorOptions o = small(4, 64, 48);
    o.confidence_noise = 0.0;
    const Predictions q = avsplat::simulate_predictions(o);
    std::vector<double> c0, rel;
    for (std::size_t i = 0; i < q.valid.size(); ++i)
        if (q.valid[i]) {
            const Camera& cam = q.true_cameras[i / (64 * 48)];
            const double d = (cam.world_to_camera * at(q.true_points, i).homogeneous()).z();
            c0.push_back(q.confidence[i]);
            rel.push_back(-std::max(double(q.true_error[i]), 1e-6 * d) / d);
            REQUIRE(q.confidence[i] == Approx(std::log(0.01 * d / std::max(double(q.true_error[i]), 1e-6 * d))).margin(1e-4));
        }
    CHECK(spearman(c0, rel) > 0.999);
}

TEST_CASE("gaussians() gives one Gaussian per valid pixel, in pixel order", "[simulator]") {
    const Predictions p = avsplat::simulate_predictions(small());
    const avsplat::GaussianCloud g = p.gaussians();
    const std::size_t valid = std::count(p.valid.begin(), p.valid.end(), 1);
    REQUIRE(g.size() == valid);
    REQUIRE(g.has_confidence());
    CHECK_NOTHROW(avsplat::validate(g));
    std::size_t j = 0;
    for (std::size_t i = 0; i < p.valid.size(); ++i) {
        if (!p.valid[i]) continue;
        REQUIRE(at(g.means, j) == at(p.points, i));
        REQUIRE(g.confidence[j] == p.confidence[i]);
        // Flat along the predicted normal; 1 sigma = half the pixel footprint (the default).
        const auto q = g.rotation(j);
        const Eigen::Matrix3d R = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).toRotationMatrix();
        REQUIRE(R.col(2).dot(at(p.normals, i)) == Approx(1.0).margin(1e-5));
        const Camera& cam = p.cameras[i / (p.width * p.height)];
        const double z = (cam.world_to_camera * at(p.points, i).homogeneous()).z();
        REQUIRE(g.scales[3 * j + 1] == Approx(0.5 * z / cam.fx).epsilon(1e-5));
        REQUIRE(g.scales[3 * j] >= g.scales[3 * j + 1]);
        ++j;
    }
}

TEST_CASE("target cameras sit between input views", "[simulator]") {
    SimulatorOptions o;
    o.views = 7;
    o.target_views = 3;
    const auto in = avsplat::input_cameras(o);
    const auto tg = avsplat::target_cameras(o);
    REQUIRE(in.size() == 7);
    REQUIRE(tg.size() == 3);
    auto azimuth = [](const Camera& c) { return std::atan2(c.position().y() - 0.1, c.position().x() - 0.25); };
    for (const Camera& t : tg) {
        double nearest = 1e9;
        for (const Camera& c : in) nearest = std::min(nearest, std::abs(azimuth(c) - azimuth(t)));
        const double spacing = std::abs(azimuth(in[1]) - azimuth(in[0]));
        CHECK(nearest == Approx(0.5 * spacing).epsilon(1e-9));  // midway between two inputs
        CHECK(t.width == o.width);
        CHECK_NOTHROW(t.validate());
    }
    o.target_views = 7;
    CHECK_THROWS_WITH(avsplat::target_cameras(o), Catch::Contains("SimulatorOptions.target_views"));
}

TEST_CASE("ground truth colours are the scene colours and misses show the background", "[simulator]") {
    SimulatorOptions o = small(4, 64, 48);
    o.supersample = 1;
    o.background = {0.2f, 0.4f, 0.6f};
    const Camera cam = avsplat::input_cameras(o)[3];
    const auto gt = avsplat::ground_truth(cam, o);
    std::size_t same = 0, hit = 0, missed = 0;
    for (std::size_t i = 0; i < gt.alpha.size(); ++i) {
        if (gt.object_id[i] < 0) {
            REQUIRE(gt.alpha[i] == 0.f);
            REQUIRE(at(gt.color, i) == Eigen::Vector3d(0.2f, 0.4f, 0.6f));
            REQUIRE(gt.depth[i] == 0.f);
            ++missed;
            continue;
        }
        ++hit;
        const Eigen::Vector3d x = cam.position() + double(gt.depth[i]) * pixel_ray(cam, i % 64 + 0.5, i / 64 + 0.5);
        const Eigen::Vector3f c = avsplat::scene_color(x, static_cast<SceneObject>(gt.object_id[i]));
        // The hit is rebuilt from a float32 depth, so a pixel right on a texture edge may flip.
        same += (c.cast<double>() - at(gt.color, i)).norm() < 1e-5;
        REQUIRE(c.minCoeff() >= 0.f);
        REQUIRE(c.maxCoeff() <= 1.f);
    }
    CHECK(missed > 0);
    CHECK(same >= hit * 99 / 100);
    // Supersampling averages: alpha is fractional on silhouettes only.
    o.supersample = 4;
    const auto ss = avsplat::ground_truth(cam, o);
    const auto fractional = std::count_if(ss.alpha.begin(), ss.alpha.end(), [](float a) { return a > 0.f && a < 1.f; });
    CHECK(fractional > 0);
    CHECK(fractional < 64 * 48 / 10);
}

TEST_CASE("simulator options and scene_color reject bad input", "[simulator]") {
    SimulatorOptions o;
    o.views = 0;
    CHECK_THROWS_WITH(avsplat::simulate_predictions(o), Catch::Contains("SimulatorOptions.views"));
    o = SimulatorOptions();
    o.depth_noise = -1.0;
    CHECK_THROWS_WITH(avsplat::simulate_predictions(o), Catch::Contains("SimulatorOptions.depth_noise"));
    o = SimulatorOptions();
    o.supersample = 0;
    CHECK_THROWS_WITH(avsplat::ground_truth(avsplat::input_cameras()[0], o), Catch::Contains("SimulatorOptions.supersample"));
    CHECK_THROWS_WITH(avsplat::scene_color(Eigen::Vector3d::Zero(), SceneObject::Background),
                      Catch::Contains("not a scene object"));
    Camera bad = avsplat::input_cameras()[0];
    bad.fx = -1.0;
    CHECK_THROWS_WITH(avsplat::ground_truth(bad), Catch::Contains("Camera.fx"));
}
