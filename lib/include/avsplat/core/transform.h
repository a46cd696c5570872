// Moving a scene between coordinate systems: similarity transforms of Gaussians, with their
// colour's spherical harmonics rotated exactly, and the axis conventions tools use.
#pragma once

#include "avsplat/core/gaussians.h"

#include <Eigen/Core>

#include <string>

namespace avsplat {

/// The matrix D (2l+1 x 2l+1) that rotates the coefficients of SH band `band` (0..3, in the
/// order of core/sh.h) with the orthogonal 3x3 matrix `rotation` (A): the colour of the rotated
/// coefficients in direction d equals the colour of the original ones in direction A^T d,
///     sum_m (D a)_m Y_m(d) = sum_m a_m Y_m(A^T d)   for every unit d.
/// A may be improper (a reflection, det -1): band l then also takes the parity (-1)^l. Exact up
/// to rounding: D is the unique matrix with that property, solved in double from the basis
/// evaluated at 64 fixed directions (a Fibonacci sphere; the band's space is closed under
/// orthogonal maps, so the least-squares fit has zero residual): this is the real-basis Wigner-D
/// matrix, found without a recurrence. Tested: the identity above holds to 1e-12, D is orthogonal
/// to 1e-13, D(AB) = D(A) D(B), and it agrees with splat-transform's SH rotation to 1e-5 (float32
/// files). Throws std::invalid_argument for a band outside
/// 0..3 or a matrix that is not orthogonal within 1e-5.
Eigen::MatrixXd sh_rotation(int band, const Eigen::Matrix3d& rotation);

/// The cloud moved by x -> scale * rotation * x + translation.
///
/// rotation     3x3 orthogonal (within 1e-5, then made exactly orthogonal by SVD); det -1
///              (a change of handedness) is allowed
/// translation  3 values, finite
/// scale        finite and > 0
/// Means become scale * R mu + t; scales are multiplied by `scale`; quaternions become q_R * q
/// (q_R the unit quaternion of R, or of -R when det R = -1, which gives the same covariance
/// R Sigma R^T); SH bands 1..3 are rotated with sh_rotation (band 0 is invariant), so a render
/// of the result from the camera moved the same way is the original render. Opacity,
/// confidence and extra channels are copied. Computed in double, rounded once to float32.
/// Throws std::invalid_argument for the arguments above or a cloud that fails validate().
GaussianCloud transform(const GaussianCloud& cloud, const Eigen::Matrix3d& rotation,
                        const Eigen::Vector3d& translation = Eigen::Vector3d::Zero(), double scale = 1.0);

/// The matrix that re-expresses coordinates in axis convention `from` in convention `to`. A
/// convention names where +x, +y, +z point, one letter each from R/L (right/left), U/D (up/down),
/// F/B (forward/back), every pair used once: "RDF" is OpenCV's (avsplat's cameras), "RUB"
/// OpenGL's and SPZ's default, "LUF" ... Conventions of different handedness give a reflection,
/// which transform() accepts. Throws std::invalid_argument naming a malformed convention.
Eigen::Matrix3d coordinate_system_change(const std::string& from, const std::string& to);

}  // namespace avsplat
