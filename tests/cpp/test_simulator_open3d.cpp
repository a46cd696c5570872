// Tests of the simulator against Open3D (an independent distance query and mesh reader); the
// rest of its tests are in test_simulator.cpp.
#include "avsplat/open3d/conversion.h"
#include "avsplat/sim/simulator.h"

#include "simulator_test_helpers.h"

#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <open3d/io/TriangleMeshIO.h>
#include <open3d/t/geometry/RaycastingScene.h>

#include <algorithm>
#include <cmath>

using avsplat::Camera;
using avsplat::Predictions;
using avsplat::SceneObject;
using avsplat::SimulatorOptions;
using namespace sim_test;
namespace core = open3d::core;

namespace {

// Unsigned distance to the default scene, independent of the simulator's ray caster: Open3D's
// RaycastingScene::ComputeDistance for the bunny, closed forms for the rectangles and the sphere.
class SceneDistance {
public:
    SceneDistance() {
        const auto mesh = avsplat::to_open3d(avsplat::bunny_mesh());
        std::vector<float> v;
        std::vector<std::uint32_t> f;
        for (const auto& x : mesh.vertices_) v.insert(v.end(), {float(x[0]), float(x[1]), float(x[2])});
        for (const auto& t : mesh.triangles_) f.insert(f.end(), {std::uint32_t(t[0]), std::uint32_t(t[1]), std::uint32_t(t[2])});
        bunny_.AddTriangles(core::Tensor(v, {int64_t(v.size() / 3), 3}, core::Float32),
                            core::Tensor(f, {int64_t(f.size() / 3), 3}, core::UInt32));
    }
    // Per point: (distance to the bunny, distance to the nearest other object).
    std::vector<std::pair<double, double>> operator()(const std::vector<Eigen::Vector3d>& p) {
        std::vector<float> q;
        for (const auto& x : p) q.insert(q.end(), {float(x[0]), float(x[1]), float(x[2])});
        const core::Tensor d = bunny_.ComputeDistance(core::Tensor(q, {int64_t(p.size()), 3}, core::Float32)).Contiguous();
        const float* dp = d.GetDataPtr<float>();
        std::vector<std::pair<double, double>> out(p.size());
        for (std::size_t i = 0; i < p.size(); ++i) {
            const Eigen::Vector3d& x = p[i];
            const Eigen::Vector3d g(std::clamp(x.x(), scene::kGroundMinX, scene::kGroundMaxX),
                                    std::clamp(x.y(), scene::kGroundMinY, scene::kGroundMaxY), 0.0);
            const Eigen::Vector3d w(std::clamp(x.x(), scene::kGroundMinX, scene::kGroundMaxX), scene::kWallY,
                                    std::clamp(x.z(), 0.0, scene::kWallHeight));
            const double other = std::min({(x - g).norm(), (x - w).norm(), std::abs((x - kCenter).norm() - scene::kSphereRadius)});
            out[i] = {dp[i], other};
        }
        return out;
    }

private:
    open3d::t::geometry::RaycastingScene bunny_;
};

}  // namespace

TEST_CASE("the ray caster agrees with sphere tracing on Open3D's distance queries", "[simulator]") {
    SceneDistance distance;
    SimulatorOptions o = small(4, 48, 36);
    o.supersample = 1;
    std::vector<Camera> cams = avsplat::input_cameras(o);
    cams.push_back(avsplat::target_cameras(o)[0]);
    std::size_t hits = 0, misses = 0;
    for (const Camera& cam : cams) {
        const auto gt = avsplat::ground_truth(cam, o);
        const std::size_t n = static_cast<std::size_t>(cam.width) * cam.height;
        const Eigen::Vector3d origin = cam.position();
        std::vector<Eigen::Vector3d> dir(n);
        for (std::size_t i = 0; i < n; ++i) dir[i] = pixel_ray(cam, i % cam.width + 0.5, i / cam.width + 0.5).normalized();
        // March every ray by the distance to the scene until it is within 1e-6 of a surface or
        // has left the scene (t > 20).
        std::vector<double> t(n, 0.0);
        std::vector<int> state(n, 0);  // 0 marching, 1 hit, 2 left
        std::vector<SceneObject> object(n, SceneObject::Background);
        for (int iter = 0; iter < 5000; ++iter) {
            std::vector<std::size_t> active;
            std::vector<Eigen::Vector3d> p;
            for (std::size_t i = 0; i < n; ++i)
                if (state[i] == 0) {
                    active.push_back(i);
                    p.push_back(origin + t[i] * dir[i]);
                }
            if (active.empty()) break;
            const auto d = distance(p);
            for (std::size_t k = 0; k < active.size(); ++k) {
                const std::size_t i = active[k];
                const double step = std::min(d[k].first, d[k].second);
                if (step < 1e-6) {
                    state[i] = 1;
                    object[i] = d[k].first <= d[k].second ? SceneObject::Bunny : SceneObject::Background;
                } else if ((t[i] += step) > 20.0) {
                    state[i] = 2;
                }
            }
        }
        for (std::size_t i = 0; i < n; ++i) {
            INFO("pixel " << i);
            REQUIRE(state[i] != 0);
            if (state[i] == 2) {
                REQUIRE(gt.object_id[i] == -1);
                ++misses;
                continue;
            }
            REQUIRE(gt.object_id[i] >= 0);
            const double t_ours = gt.depth[i] * pixel_ray(cam, i % cam.width + 0.5, i / cam.width + 0.5).norm();
            REQUIRE(t_ours == Approx(t[i]).margin(2e-4));
            REQUIRE((object[i] == SceneObject::Bunny) == (gt.object_id[i] == int(SceneObject::Bunny)));
            ++hits;
        }
    }
    CHECK(hits > 1000);
    CHECK(misses > 0);
}

TEST_CASE("noise-free predictions lie on the true surface", "[simulator]") {
    const SimulatorOptions o = noise_free(small(3, 48, 36));
    const Predictions p = avsplat::simulate_predictions(o);
    SceneDistance distance;
    std::vector<Eigen::Vector3d> pts;
    std::vector<std::size_t> idx;
    std::size_t count[4] = {0, 0, 0, 0};
    for (std::size_t i = 0; i < p.valid.size(); ++i) {
        if (!p.valid[i]) {
            CHECK(p.object_id[i] == -1);
            continue;
        }
        const Eigen::Vector3d x = at(p.points, i);
        REQUIRE(p.true_error[i] < 1e-6f);
        REQUIRE((x - at(p.true_points, i)).norm() < 1e-6);
        switch (static_cast<SceneObject>(p.object_id[i])) {
            case SceneObject::Ground: REQUIRE(std::abs(x.z()) < 1e-6); break;
            case SceneObject::Wall: REQUIRE(std::abs(x.y() - scene::kWallY) < 1e-6); break;
            case SceneObject::Sphere: REQUIRE(std::abs((x - kCenter).norm() - scene::kSphereRadius) < 1e-6); break;
            case SceneObject::Bunny:
                pts.push_back(x);
                idx.push_back(i);
                break;
            default: FAIL("unknown object id");
        }
        ++count[p.object_id[i]];
    }
    for (int k = 0; k < 4; ++k) CHECK(count[k] > 20);  // every object is seen
    const auto d = distance(pts);
    for (std::size_t k = 0; k < pts.size(); ++k) REQUIRE(d[k].first < 1e-5);
    for (std::size_t s = 0; s < p.cameras.size(); ++s)
        CHECK(p.cameras[s].world_to_camera == p.true_cameras[s].world_to_camera);
}

TEST_CASE("the embedded bunny is lib/data/bunny.ply as Open3D reads it", "[simulator]") {
    open3d::geometry::TriangleMesh file;
    REQUIRE(open3d::io::ReadTriangleMesh(AVSPLAT_SOURCE_DIR "/lib/data/bunny.ply", file));
    const auto mesh = avsplat::to_open3d(avsplat::bunny_mesh());
    REQUIRE(mesh.vertices_.size() == file.vertices_.size());
    REQUIRE(mesh.triangles_.size() == file.triangles_.size());
    CHECK(mesh.triangles_.size() == 8000);
    for (std::size_t i = 0; i < mesh.vertices_.size(); ++i)
        REQUIRE((mesh.vertices_[i] - (file.vertices_[i] - Eigen::Vector3d(0, 0, scene::kBunnySink))).norm() < 1e-6);
    for (std::size_t f = 0; f < mesh.triangles_.size(); ++f) REQUIRE(mesh.triangles_[f] == file.triangles_[f]);
    const auto box = mesh.GetAxisAlignedBoundingBox();
    CHECK(box.GetExtent().maxCoeff() == Approx(1.0).epsilon(1e-5));
}
