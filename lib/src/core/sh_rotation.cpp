// sh_rotation (core/transform.h): the exact rotation of one real SH band.
//
// A band's functions span a space that every orthogonal map keeps, so Y(A^T d) = M Y(d) for one
// (2l+1)-square matrix M. Sampling both sides at more directions than unknowns and solving the
// normal equations in double gives M exactly up to rounding (the fit has no residual); the
// coefficients then rotate with D = M^T. The basis comes from eval_sh itself (unit
// coefficients), so the matrices follow the renderer's constants and signs by construction.
#include "avsplat/core/transform.h"

#include "avsplat/core/sh.h"

#include <Eigen/Cholesky>
#include <Eigen/Dense>

#include <cmath>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

constexpr int kDirections = 64;

// Y_k(d) for the 16 functions of degrees 0..3 at unit direction d.
Eigen::Matrix<double, 16, 1> basis(const Eigen::Vector3d& d) {
    Eigen::Matrix<double, 16, 1> y;
    float unit[16 * 3] = {};
    for (int k = 0; k < 16; ++k) {
        unit[3 * k] = 1.0f;
        double rgb[3];
        sh::eval_sh<double>(3, unit, d.x(), d.y(), d.z(), rgb);
        y[k] = rgb[0];
        unit[3 * k] = 0.0f;
    }
    return y;
}

// A Fibonacci sphere: well spread, so the normal equations are well conditioned.
Eigen::Vector3d direction(int i) {
    const double golden = M_PI * (3.0 - std::sqrt(5.0));
    const double z = 1.0 - (2.0 * i + 1.0) / kDirections;
    const double r = std::sqrt(1.0 - z * z);
    return {r * std::cos(golden * i), r * std::sin(golden * i), z};
}

}  // namespace

Eigen::MatrixXd sh_rotation(int band, const Eigen::Matrix3d& rotation) {
    if (band < 0 || band > kMaxShDegree)
        throw std::invalid_argument("sh_rotation: band " + std::to_string(band) + " is outside 0..3");
    if (!rotation.allFinite() || ((rotation.transpose() * rotation) - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-5)
        throw std::invalid_argument("sh_rotation: rotation is not an orthogonal 3x3 matrix (within 1e-5)");
    const int first = band * band, size = 2 * band + 1;
    Eigen::MatrixXd y(size, kDirections), y_rot(size, kDirections);
    for (int i = 0; i < kDirections; ++i) {
        const Eigen::Vector3d d = direction(i);
        y.col(i) = basis(d).segment(first, size);
        y_rot.col(i) = basis(rotation.transpose() * d).segment(first, size);
    }
    // M Y = Y_rot in least squares: M = Y_rot Y^T (Y Y^T)^-1, and D = M^T.
    const Eigen::MatrixXd gram = y * y.transpose();
    return gram.ldlt().solve(y * y_rot.transpose());
}

}  // namespace avsplat
