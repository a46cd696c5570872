// transform and coordinate_system_change (core/transform.h).
#include "avsplat/core/transform.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <Eigen/SVD>

#include <array>
#include <cctype>
#include <cmath>
#include <stdexcept>
#include <string>

namespace avsplat {

GaussianCloud transform(const GaussianCloud& cloud, const Eigen::Matrix3d& rotation, const Eigen::Vector3d& translation,
                        double scale) {
    validate(cloud);
    if (!rotation.allFinite() || ((rotation.transpose() * rotation) - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-5)
        throw std::invalid_argument("transform: rotation is not an orthogonal 3x3 matrix (within 1e-5)");
    if (!translation.allFinite()) throw std::invalid_argument("transform: translation is not finite");
    if (!(std::isfinite(scale) && scale > 0))
        throw std::invalid_argument("transform: scale must be finite and > 0, got " + std::to_string(scale));
    // The nearest orthogonal matrix, so that a rotation given in float32 rotates exactly.
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(rotation, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Eigen::Matrix3d A = svd.matrixU() * svd.matrixV().transpose();
    const bool reflection = A.determinant() < 0;
    const Eigen::Quaterniond qa(reflection ? Eigen::Matrix3d(-A) : A);

    const int K = cloud.sh_coeffs();
    std::array<Eigen::MatrixXd, kMaxShDegree + 1> D;
    for (int l = 1; l <= cloud.sh_degree; ++l) D[l] = sh_rotation(l, A);

    GaussianCloud out = cloud;
    const std::size_t n = cloud.size();
    const long long n_ll = static_cast<long long>(n);
#pragma omp parallel for schedule(static)
    for (long long ii = 0; ii < n_ll; ++ii) {
        const std::size_t i = static_cast<std::size_t>(ii);
        const Eigen::Vector3d mu(cloud.means[3 * i], cloud.means[3 * i + 1], cloud.means[3 * i + 2]);
        const Eigen::Vector3d m = scale * (A * mu) + translation;
        for (int a = 0; a < 3; ++a) {
            out.means[3 * i + a] = static_cast<float>(m[a]);
            out.scales[3 * i + a] = static_cast<float>(scale * cloud.scales[3 * i + a]);
        }
        const float* r = &cloud.rotations[4 * i];
        const Eigen::Quaterniond q = qa * Eigen::Quaterniond(r[0], r[1], r[2], r[3]);
        out.rotations[4 * i + 0] = static_cast<float>(q.w());
        out.rotations[4 * i + 1] = static_cast<float>(q.x());
        out.rotations[4 * i + 2] = static_cast<float>(q.y());
        out.rotations[4 * i + 3] = static_cast<float>(q.z());
        const float* s = &cloud.sh[i * 3 * static_cast<std::size_t>(K)];
        float* o = &out.sh[i * 3 * static_cast<std::size_t>(K)];
        for (int l = 1; l <= cloud.sh_degree; ++l) {
            const int first = l * l, size = 2 * l + 1;
            for (int c = 0; c < 3; ++c)
                for (int a = 0; a < size; ++a) {
                    double v = 0;
                    for (int b = 0; b < size; ++b) v += D[l](a, b) * s[3 * (first + b) + c];
                    o[3 * (first + a) + c] = static_cast<float>(v);
                }
        }
    }
    return out;
}

Eigen::Matrix3d coordinate_system_change(const std::string& from, const std::string& to) {
    // Columns: where each axis of the convention points, in RDF terms.
    auto axes = [](const std::string& c, const char* which) {
        if (c.size() != 3)
            throw std::invalid_argument(std::string("coordinate_system_change: ") + which + " \"" + c +
                                        "\" is not three letters from R/L, U/D, F/B");
        Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
        bool used[3] = {false, false, false};
        for (int k = 0; k < 3; ++k) {
            const char ch = static_cast<char>(std::toupper(static_cast<unsigned char>(c[static_cast<std::size_t>(k)])));
            int axis = -1;
            double sign = 1;
            switch (ch) {
                case 'R': axis = 0; break;
                case 'L': axis = 0; sign = -1; break;
                case 'D': axis = 1; break;
                case 'U': axis = 1; sign = -1; break;
                case 'F': axis = 2; break;
                case 'B': axis = 2; sign = -1; break;
                default: break;
            }
            if (axis < 0 || used[axis])
                throw std::invalid_argument(std::string("coordinate_system_change: ") + which + " \"" + c +
                                            "\" is not three letters from R/L, U/D, F/B, one of each pair");
            used[axis] = true;
            m(axis, k) = sign;
        }
        return m;
    };
    return axes(to, "to").transpose() * axes(from, "from");
}

}  // namespace avsplat
