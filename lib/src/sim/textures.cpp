// The default scene's procedural textures: value noise and a colour per object, functions of
// the 3D point alone (so a colour error is always a geometry error).
#include "avsplat/sim/simulator.h"

#include "sim/random.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

using sim::kPi;
using sim::splitmix64;
using sim::to_unit;

// Procedural textures: value noise on an integer lattice hashed with splitmix64, so a colour is
// a pure function of the point.

double lattice(std::int64_t i, std::int64_t j, std::int64_t k, std::uint64_t salt) {
    std::uint64_t h = splitmix64(salt ^ static_cast<std::uint64_t>(i));
    h = splitmix64(h ^ static_cast<std::uint64_t>(j));
    h = splitmix64(h ^ static_cast<std::uint64_t>(k));
    return to_unit(h);
}

double smooth(double t) { return t * t * (3.0 - 2.0 * t); }

// Trilinear value noise in [0, 1) with smoothstep weights.
double value_noise(double x, double y, double z, std::uint64_t salt) {
    const double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
    const auto ix = static_cast<std::int64_t>(fx), iy = static_cast<std::int64_t>(fy),
               iz = static_cast<std::int64_t>(fz);
    const double u = smooth(x - fx), v = smooth(y - fy), w = smooth(z - fz);
    double c[2][2];
    for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b)
            c[a][b] = lattice(ix + a, iy + b, iz, salt) * (1.0 - w) + lattice(ix + a, iy + b, iz + 1, salt) * w;
    const double c0 = c[0][0] * (1.0 - v) + c[0][1] * v;
    const double c1 = c[1][0] * (1.0 - v) + c[1][1] * v;
    return c0 * (1.0 - u) + c1 * u;
}

// Fractal sum of `octaves` octaves from frequency `freq` (amplitude halving), in [0, 1).
double fbm(const Eigen::Vector3d& p, double freq, int octaves, std::uint64_t salt) {
    double sum = 0.0, amp = 1.0, norm = 0.0;
    for (int o = 0; o < octaves; ++o) {
        sum += amp * value_noise(p.x() * freq, p.y() * freq, p.z() * freq, salt + o);
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    return sum / norm;
}

std::int64_t cell(double x, double size) { return static_cast<std::int64_t>(std::floor(x / size)); }

Eigen::Vector3d ground_color(const Eigen::Vector3d& p) {
    const double tile = 0.5;
    const std::int64_t tx = cell(p.x(), tile), ty = cell(p.y(), tile);
    Eigen::Vector3d c = ((tx + ty) & 1) ? Eigen::Vector3d(0.86, 0.78, 0.60) : Eigen::Vector3d(0.40, 0.29, 0.20);
    c *= ((cell(p.x(), 0.05) + cell(p.y(), 0.05)) & 1) ? 1.08 : 0.92;
    const Eigen::Vector3d q(p.x(), p.y(), 0.0);
    c *= 0.75 + 0.5 * fbm(q, 6.0, 4, 11);
    c += Eigen::Vector3d(0.05, -0.02, 0.04) * (fbm(q, 2.0, 3, 17) - 0.5);
    const double jx = std::abs(p.x() / tile - std::round(p.x() / tile)) * tile;
    const double jy = std::abs(p.y() / tile - std::round(p.y() / tile)) * tile;
    if (std::min(jx, jy) < 0.008) c = Eigen::Vector3d(0.12, 0.11, 0.10);
    return c;
}

Eigen::Vector3d wall_color(const Eigen::Vector3d& p) {
    const double brick_w = 0.3, brick_h = 0.12, mortar = 0.012;
    const std::int64_t row = cell(p.z(), brick_h);
    const double u = p.x() + ((row & 1) ? 0.5 * brick_w : 0.0);
    const std::int64_t col = cell(u, brick_w);
    const double lu = u - static_cast<double>(col) * brick_w;
    const double lv = p.z() - static_cast<double>(row) * brick_h;
    const Eigen::Vector3d q(p.x(), 0.0, p.z());
    if (lu < mortar || lv < mortar)
        return Eigen::Vector3d(0.78, 0.77, 0.72) * (0.9 + 0.2 * fbm(q, 40.0, 2, 23));
    Eigen::Vector3d c = Eigen::Vector3d(0.62, 0.26, 0.17) * (0.75 + 0.5 * lattice(col, row, 0, 29));
    c += Eigen::Vector3d::Constant(0.1 * (lattice(col, row, 1, 31) - 0.5));
    return c * (0.85 + 0.3 * fbm(q, 25.0, 3, 37));
}

Eigen::Vector3d bunny_color(const Eigen::Vector3d& p) {
    const double n = fbm(p, 3.0, 4, 41);
    const double t = smooth(std::clamp((n - 0.35) / 0.3, 0.0, 1.0));
    Eigen::Vector3d c = Eigen::Vector3d(0.93, 0.84, 0.58) * (1.0 - t) + Eigen::Vector3d(0.35, 0.58, 0.30) * t;
    const double stripe = 0.5 + 0.5 * std::sin(2.0 * kPi * (p.z() / 0.05 + 1.5 * fbm(p, 2.0, 3, 43)));
    return c * (0.8 + 0.3 * stripe);
}

Eigen::Vector3d sphere_color(const Eigen::Vector3d& p) {
    const Eigen::Vector3d center(default_scene::kSphereCenter[0], default_scene::kSphereCenter[1],
                                 default_scene::kSphereCenter[2]);
    const Eigen::Vector3d q = (p - center) / default_scene::kSphereRadius;
    const double lon = std::atan2(q.y(), q.x());
    const double lat = std::asin(std::clamp(q.z() / std::max(q.norm(), 1e-300), -1.0, 1.0));
    const std::int64_t i = cell(lon, 2.0 * kPi / 16.0), j = cell(lat, kPi / 8.0);
    const Eigen::Vector3d c = ((i + j) & 1) ? Eigen::Vector3d(0.92, 0.92, 0.95) : Eigen::Vector3d(0.13, 0.27, 0.70);
    return c * (0.9 + 0.2 * fbm(q, 8.0, 3, 47));
}

}  // namespace

Eigen::Vector3f scene_color(const Eigen::Vector3d& p, SceneObject object) {
    Eigen::Vector3d c;
    switch (object) {
        case SceneObject::Ground: c = ground_color(p); break;
        case SceneObject::Wall: c = wall_color(p); break;
        case SceneObject::Bunny: c = bunny_color(p); break;
        case SceneObject::Sphere: c = sphere_color(p); break;
        default:
            throw std::invalid_argument("scene_color: object " + std::to_string(static_cast<int>(object)) +
                                        " is not a scene object (0..3)");
    }
    return c.cwiseMax(0.0).cwiseMin(1.0).cast<float>();
}

}  // namespace avsplat
