// transform, sh_rotation and coordinate_system_change (core/transform.h) against references
// written here: brute-force SH evaluation at rotated directions, quaternion algebra, and the
// renderer (a moved scene seen from the camera moved with it is the same image).
#include "avsplat/core/camera.h"
#include "avsplat/core/sh.h"
#include "avsplat/core/transform.h"
#include "avsplat/render/render.h"

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <cmath>
#include <random>

using avsplat::GaussianCloud;

namespace {

Eigen::Matrix3d random_rotation(std::mt19937& rng) {
    std::normal_distribution<double> g;
    return Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
}

// The colour of band `l`'s coefficients a (2l+1 values) in direction d, by the renderer's own
// evaluation (the other bands zero).
double band_colour(int l, const Eigen::VectorXd& a, const Eigen::Vector3d& d) {
    float coeffs[16 * 3] = {};
    for (int m = 0; m < 2 * l + 1; ++m) coeffs[3 * (l * l + m)] = static_cast<float>(a[m]);
    double rgb[3];
    avsplat::sh::eval_sh<double>(3, coeffs, d.x(), d.y(), d.z(), rgb);
    return rgb[0];
}

GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f), p(0.f, 1.f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = 0.6f * u(rng);
    for (auto& v : c.scales) v = 0.01f + 0.05f * p(rng);
    for (auto& v : c.rotations) v = u(rng);
    for (auto& v : c.opacities) v = 0.2f + 0.7f * p(rng);
    for (auto& v : c.sh) v = 0.8f * u(rng);
    return c;
}

}  // namespace

TEST_CASE("sh_rotation matches evaluation at rotated directions", "[transform][sh]") {
    std::mt19937 rng(1);
    std::normal_distribution<double> g;
    for (int trial = 0; trial < 20; ++trial) {
        Eigen::Matrix3d A = random_rotation(rng);
        if (trial % 4 == 3) A = -A;                                   // improper: an inversion
        if (trial % 4 == 2) A = A * Eigen::Vector3d(1, 1, -1).asDiagonal().toDenseMatrix();  // a mirror
        for (int l = 0; l <= 3; ++l) {
            const Eigen::MatrixXd D = avsplat::sh_rotation(l, A);
            REQUIRE(D.rows() == 2 * l + 1);
            // Orthogonal (the real SH are orthonormal on the sphere).
            CHECK((D.transpose() * D - Eigen::MatrixXd::Identity(2 * l + 1, 2 * l + 1)).cwiseAbs().maxCoeff() < 1e-13);
            Eigen::VectorXd a(2 * l + 1);
            for (int m = 0; m < 2 * l + 1; ++m) a[m] = g(rng);
            for (int k = 0; k < 10; ++k) {
                const Eigen::Vector3d d = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
                // Float coefficients in band_colour: compare at float precision of a.
                CHECK(band_colour(l, D * a, d) == Approx(band_colour(l, a, A.transpose() * d)).margin(2e-6));
            }
        }
    }
    // Band 1 of this basis is (-y, z, -x): rotating a about z by 90 degrees maps x to y.
    const Eigen::Matrix3d rz = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::MatrixXd D1 = avsplat::sh_rotation(1, rz);
    Eigen::Matrix3d expect;
    expect << 0, 0, 1, 0, 1, 0, -1, 0, 0;  // hand-derived: Y(-y,z,-x) under d -> Rz^T d
    CHECK((D1 - Eigen::MatrixXd(expect)).cwiseAbs().maxCoeff() < 1e-14);
    CHECK_THROWS_AS(avsplat::sh_rotation(4, rz), std::invalid_argument);
    CHECK_THROWS_WITH(avsplat::sh_rotation(1, 2 * rz), Catch::Contains("not an orthogonal"));
}

TEST_CASE("sh_rotation composes and inverts", "[transform][sh]") {
    std::mt19937 rng(2);
    const Eigen::Matrix3d A = random_rotation(rng), B = random_rotation(rng);
    for (int l = 1; l <= 3; ++l) {
        const Eigen::MatrixXd dab = avsplat::sh_rotation(l, A * B);
        CHECK((dab - avsplat::sh_rotation(l, A) * avsplat::sh_rotation(l, B)).cwiseAbs().maxCoeff() < 1e-13);
        CHECK((avsplat::sh_rotation(l, A.transpose()) * avsplat::sh_rotation(l, A) -
               Eigen::MatrixXd::Identity(2 * l + 1, 2 * l + 1)).cwiseAbs().maxCoeff() < 1e-13);
    }
}

TEST_CASE("transform composes, inverts and checks its arguments", "[transform]") {
    std::mt19937 rng(3);
    const GaussianCloud c = random_cloud(200, 3, 4);
    const Eigen::Matrix3d A = random_rotation(rng), B = random_rotation(rng);
    const Eigen::Vector3d ta(0.1, -0.2, 0.3), tb(1, 2, 3);
    // B (2 A x + ta) + tb = 2 B A x + (B ta + tb)
    const GaussianCloud two = avsplat::transform(avsplat::transform(c, A, ta, 2.0), B, tb);
    const GaussianCloud one = avsplat::transform(c, B * A, B * ta + tb, 2.0);
    auto close = [](const std::vector<float>& x, const std::vector<float>& y, double tol) {
        REQUIRE(x.size() == y.size());
        double worst = 0;
        for (std::size_t i = 0; i < x.size(); ++i) worst = std::max(worst, double(std::fabs(x[i] - y[i])));
        return worst <= tol;
    };
    CHECK(close(two.means, one.means, 1e-5));
    CHECK(close(two.scales, one.scales, 1e-7));
    CHECK(close(two.sh, one.sh, 1e-5));
    // Quaternions agree up to their free sign (q and -q are the same rotation).
    auto close_up_to_sign = [](const std::vector<float>& x, const std::vector<float>& y, double tol) {
        REQUIRE(x.size() == y.size());
        double worst = 0;
        for (std::size_t i = 0; i < x.size(); i += 4) {
            double dot = 0;
            for (int k = 0; k < 4; ++k) dot += double(x[i + k]) * y[i + k];
            const double s = dot < 0 ? -1 : 1;
            for (int k = 0; k < 4; ++k) worst = std::max(worst, std::fabs(x[i + k] - s * y[i + k]));
        }
        return worst <= tol;
    };
    CHECK(close_up_to_sign(two.rotations, one.rotations, 1e-5));
    // Inverse: x = A^T (y - t) / s.
    const GaussianCloud moved = avsplat::transform(c, A, ta, 2.0);
    const GaussianCloud back = avsplat::transform(moved, A.transpose(), -A.transpose() * ta / 2.0, 0.5);
    CHECK(close(back.means, c.means, 1e-5));
    CHECK(close(back.scales, c.scales, 1e-7));
    CHECK(close(back.sh, c.sh, 1e-5));
    CHECK(close_up_to_sign(back.rotations, c.rotations, 1e-5));
    CHECK(back.opacities == c.opacities);
    // The covariance moves as A Sigma A^T, for a reflection too.
    const Eigen::Matrix3d M = A * Eigen::Vector3d(-1, 1, 1).asDiagonal().toDenseMatrix();
    const GaussianCloud mirrored = avsplat::transform(c, M);
    for (std::size_t i = 0; i < c.size(); i += 37)
        CHECK((mirrored.covariance(i) - M * c.covariance(i) * M.transpose()).cwiseAbs().maxCoeff() < 1e-8);

    CHECK_THROWS_WITH(avsplat::transform(c, A, ta, 0.0), Catch::Contains("scale must be finite and > 0"));
    CHECK_THROWS_WITH(avsplat::transform(c, 1.1 * A), Catch::Contains("not an orthogonal"));
    CHECK_THROWS_WITH(avsplat::transform(c, A, Eigen::Vector3d(NAN, 0, 0)), Catch::Contains("translation"));
}

TEST_CASE("a transformed scene renders as the original from the transformed camera", "[transform][render]") {
    std::mt19937 rng(4);
    const GaussianCloud c = random_cloud(300, 3, 5);
    const avsplat::Camera cam = avsplat::Camera::look_at({0.3, -0.4, -2.5}, {0, 0, 0}, {0, -1, 0}, 50, 96, 72);
    avsplat::RenderOptions opt;
    opt.precision = avsplat::Precision::Float64;
    const avsplat::RenderResult ref = avsplat::render(c, cam, opt);
    for (double s : {1.0, 2.5}) {
        const Eigen::Matrix3d R = random_rotation(rng);
        const Eigen::Vector3d t(0.5, -1.0, 2.0);
        const GaussianCloud moved = avsplat::transform(c, R, t, s);
        // Camera coordinates scale by s: W' = [Rc R^T | s tc - Rc R^T t], near and far times s.
        const Eigen::Matrix3d Rc = cam.world_to_camera.topLeftCorner<3, 3>();
        const Eigen::Vector3d tc = cam.world_to_camera.topRightCorner<3, 1>();
        Eigen::Matrix4d W = Eigen::Matrix4d::Identity();
        W.topLeftCorner<3, 3>() = Rc * R.transpose();
        W.topRightCorner<3, 1>() = s * tc - Rc * R.transpose() * t;
        const avsplat::Camera cam2(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height, W, cam.near * s, cam.far * s);
        const avsplat::RenderResult img = avsplat::render(moved, cam2, opt);
        double worst = 0, signal = 0;
        for (std::size_t k = 0; k < ref.color.size(); ++k) {
            worst = std::max(worst, double(std::fabs(img.color[k] - ref.color[k])));
            signal = std::max(signal, double(ref.color[k]));
        }
        INFO("scale " << s);
        CHECK(signal > 0.2);  // the view sees the scene
        CHECK(worst < 1e-5);
        // Without rotating the SH (only the geometry moved) the image differs: the test can fail.
        GaussianCloud unrotated = moved;
        unrotated.sh = c.sh;
        const avsplat::RenderResult wrong = avsplat::render(unrotated, cam2, opt);
        double off = 0;
        for (std::size_t k = 0; k < ref.color.size(); ++k) off = std::max(off, double(std::fabs(wrong.color[k] - ref.color[k])));
        CHECK(off > 1e-2);
    }
}

TEST_CASE("coordinate_system_change maps axis conventions", "[transform]") {
    Eigen::Matrix3d flip_yz = Eigen::Vector3d(1, -1, -1).asDiagonal();
    CHECK(avsplat::coordinate_system_change("RUB", "RDF") == flip_yz);
    CHECK(avsplat::coordinate_system_change("rdf", "RDF") == Eigen::Matrix3d::Identity());
    // RDF -> LUF: x and y flip, a rotation of 180 degrees about z.
    CHECK(avsplat::coordinate_system_change("RDF", "LUF").determinant() == 1.0);
    // A point 1 forward in RUB is z = -1; in RDF z = +1.
    CHECK((avsplat::coordinate_system_change("RUB", "RDF") * Eigen::Vector3d(0, 0, -1)).z() == 1.0);
    // Right-handed to left-handed: a reflection.
    CHECK(avsplat::coordinate_system_change("RUB", "RUF").determinant() == -1.0);
    CHECK_THROWS_WITH(avsplat::coordinate_system_change("RRF", "RDF"), Catch::Contains("\"RRF\""));
    CHECK_THROWS_AS(avsplat::coordinate_system_change("RD", "RDF"), std::invalid_argument);
}
