#include "avsplat/sim/simulator.h"

#include "avsplat/io/ply_data.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace embedded {
// lib/data/bunny.ply, compiled in by cmake/embed_file.cmake.
extern const unsigned char bunny_ply[];
extern const std::size_t bunny_ply_size;
}  // namespace embedded

namespace {

constexpr double kPi = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------------
// The embedded bunny (lib/data/bunny.ply, as scripts/convert_bunny.py writes it), read with the
// generic PLY layer. A file without a triangle mesh means a wrong file was embedded, which is a
// build error, not bad input.

struct Mesh {
    std::vector<float> vertices;           // n x 3
    std::vector<std::uint32_t> triangles;  // m x 3
};

Mesh parse_bunny() {
    auto fail = [](const std::string& what) {
        throw std::logic_error("embedded bunny.ply: " + what + " (rebuild from lib/data/bunny.ply)");
    };
    const PlyData ply = parse_ply_data(embedded::bunny_ply, embedded::bunny_ply_size, "embedded bunny.ply");
    const PlyElement* vertex = ply.find("vertex");
    const PlyElement* face = ply.find("face");
    if (!vertex || !face) fail("no vertex or face element");
    const PlyColumn* xyz[3] = {vertex->find("x"), vertex->find("y"), vertex->find("z")};
    const PlyColumn* indices = face->find("vertex_indices");
    if (!xyz[0] || !xyz[1] || !xyz[2] || !indices || !indices->is_list) fail("no x, y, z or vertex_indices");
    const std::size_t n = static_cast<std::size_t>(vertex->count);
    const std::size_t m = static_cast<std::size_t>(face->count);
    Mesh mesh;
    mesh.vertices.resize(3 * n);
    for (std::size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) mesh.vertices[3 * i + a] = static_cast<float>(xyz[a]->values[i]);
    mesh.triangles.resize(3 * m);
    for (std::size_t f = 0; f < m; ++f) {
        if (indices->offsets[f + 1] - indices->offsets[f] != 3) fail("a face is not a triangle");
        for (int c = 0; c < 3; ++c) {
            const double v = indices->values[indices->offsets[f] + c];
            if (!(v >= 0 && v < double(n))) fail("a vertex index is out of range");
            mesh.triangles[3 * f + c] = static_cast<std::uint32_t>(v);
        }
    }
    for (std::size_t i = 0; i < n; ++i) mesh.vertices[3 * i + 2] -= static_cast<float>(default_scene::kBunnySink);
    return mesh;
}

const Mesh& bunny() {
    static const Mesh mesh = parse_bunny();  // parsed once, thread-safe initialisation
    return mesh;
}

// ---------------------------------------------------------------------------------------------
// Procedural textures: value noise on an integer lattice hashed with splitmix64, so a colour is
// a pure function of the point.

std::uint64_t splitmix64(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

double to_unit(std::uint64_t h) { return static_cast<double>(h >> 11) * 0x1.0p-53; }

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

// ---------------------------------------------------------------------------------------------
// Ray casting. Open3D 0.16's RaycastingScene::CastRays finds no hits when Open3D is linked
// against Debian 12's system Embree (3.13.5; a ray straight at a unit box misses, while
// ComputeDistance works), so rays are intersected here, in double: the planes and the sphere
// exactly, the bunny through a bounding volume hierarchy with the Moller-Trumbore test. The
// tests hold the hits to Open3D's ComputeDistance.

struct Hit {
    double t = std::numeric_limits<double>::infinity();  // in units of the ray direction
    SceneObject object = SceneObject::Background;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();     // unit, facing the ray origin
};

// A binary BVH over a triangle mesh: median split of the centroids along the longest axis,
// leaves of at most 4 triangles.
class TriangleBvh {
public:
    explicit TriangleBvh(const Mesh& mesh) {
        const std::size_t m = mesh.triangles.size() / 3;
        tri_.resize(m);
        for (std::size_t f = 0; f < m; ++f)
            for (int c = 0; c < 3; ++c)
                tri_[f].v[c] = Eigen::Map<const Eigen::Vector3f>(&mesh.vertices[3 * mesh.triangles[3 * f + c]]).cast<double>();
        order_.resize(m);
        for (std::size_t f = 0; f < m; ++f) order_[f] = f;
        nodes_.reserve(2 * m);
        build(0, m);
    }

    // The nearest triangle hit with t in [t_min, t_best) replaces t_best and normal (the
    // unnormalised geometric normal); returns whether there was one.
    bool intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& inv_d,
                   double t_min, double& t_best, Eigen::Vector3d& normal) const {
        bool hit = false;
        std::size_t stack[64];
        int top = 0;
        stack[top++] = 0;
        while (top > 0) {
            const Node& node = nodes_[stack[--top]];
            if (!box_hit(node, o, inv_d, t_min, t_best)) continue;
            if (node.count > 0) {
                for (std::size_t k = node.first; k < node.first + node.count; ++k) {
                    const Tri& tri = tri_[order_[k]];
                    double t;
                    Eigen::Vector3d n;
                    if (triangle_hit(tri, o, d, t, n) && t >= t_min && t < t_best) {
                        t_best = t;
                        normal = n;
                        hit = true;
                    }
                }
            } else {
                stack[top++] = node.right;
                stack[top++] = node.first;  // left child, visited first
            }
        }
        return hit;
    }

private:
    struct Tri {
        Eigen::Vector3d v[3];
    };
    struct Node {
        Eigen::Vector3d lo, hi;
        std::size_t first = 0;  // leaf: first index into order_; inner: left child
        std::size_t right = 0;  // inner: right child
        std::size_t count = 0;  // leaf: triangle count; inner: 0
    };

    std::size_t build(std::size_t begin, std::size_t end) {
        const std::size_t id = nodes_.size();
        nodes_.emplace_back();
        Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
        Eigen::Vector3d hi = -lo, clo = lo, chi = hi;
        for (std::size_t k = begin; k < end; ++k) {
            const Tri& t = tri_[order_[k]];
            for (const auto& v : t.v) {
                lo = lo.cwiseMin(v);
                hi = hi.cwiseMax(v);
            }
            const Eigen::Vector3d c = (t.v[0] + t.v[1] + t.v[2]) / 3.0;
            clo = clo.cwiseMin(c);
            chi = chi.cwiseMax(c);
        }
        nodes_[id].lo = lo;
        nodes_[id].hi = hi;
        if (end - begin <= 4) {
            nodes_[id].first = begin;
            nodes_[id].count = end - begin;
            return id;
        }
        Eigen::Index axis;
        (chi - clo).maxCoeff(&axis);
        const std::size_t mid = (begin + end) / 2;
        // Ties broken by index, so the tree (and the hit among equal t) is deterministic.
        std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                         [&](std::size_t a, std::size_t b) {
                             const double ca = tri_[a].v[0][axis] + tri_[a].v[1][axis] + tri_[a].v[2][axis];
                             const double cb = tri_[b].v[0][axis] + tri_[b].v[1][axis] + tri_[b].v[2][axis];
                             return ca < cb || (ca == cb && a < b);
                         });
        const std::size_t left = build(begin, mid);
        const std::size_t right = build(mid, end);
        nodes_[id].first = left;
        nodes_[id].right = right;
        return id;
    }

    static bool box_hit(const Node& n, const Eigen::Vector3d& o, const Eigen::Vector3d& inv_d,
                        double t_min, double t_max) {
        for (int a = 0; a < 3; ++a) {
            double t0 = (n.lo[a] - o[a]) * inv_d[a], t1 = (n.hi[a] - o[a]) * inv_d[a];
            if (t0 > t1) std::swap(t0, t1);
            // NaN (0 * inf, a ray in the slab's plane) compares false and keeps the bounds.
            if (t0 > t_min) t_min = t0;
            if (t1 < t_max) t_max = t1;
            if (t_min > t_max) return false;
        }
        return true;
    }

    // Moller-Trumbore; n is the unnormalised geometric normal (v1 - v0) x (v2 - v0).
    static bool triangle_hit(const Tri& tri, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                             double& t, Eigen::Vector3d& n) {
        const Eigen::Vector3d e1 = tri.v[1] - tri.v[0], e2 = tri.v[2] - tri.v[0];
        const Eigen::Vector3d p = d.cross(e2);
        const double det = e1.dot(p);
        if (det == 0.0) return false;  // parallel, or a degenerate triangle
        const double inv = 1.0 / det;
        const Eigen::Vector3d s = o - tri.v[0];
        const double u = s.dot(p) * inv;
        if (u < 0.0 || u > 1.0) return false;
        const Eigen::Vector3d q = s.cross(e1);
        const double v = d.dot(q) * inv;
        if (v < 0.0 || u + v > 1.0) return false;
        t = e2.dot(q) * inv;
        n = e1.cross(e2);
        return true;
    }

    std::vector<Tri> tri_;
    std::vector<std::size_t> order_;
    std::vector<Node> nodes_;
};

class Scene {
public:
    Scene() : bunny_(bunny()) {}

    // The nearest hit of ray o + t d (d not normalised) with t in [t_min, t_max].
    Hit cast(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min, double t_max) const {
        using namespace default_scene;
        Hit h;
        h.t = t_max;
        auto take = [&](double t, SceneObject object, const Eigen::Vector3d& normal) {
            if (t >= t_min && t <= h.t) {
                h.t = t;
                h.object = object;
                h.normal = normal;
            }
        };
        if (d.z() != 0.0) {
            const double t = -o.z() / d.z();
            const Eigen::Vector3d p = o + t * d;
            if (p.x() >= kGroundMinX && p.x() <= kGroundMaxX && p.y() >= kGroundMinY && p.y() <= kGroundMaxY)
                take(t, SceneObject::Ground, Eigen::Vector3d::UnitZ());
        }
        if (d.y() != 0.0) {
            const double t = (kWallY - o.y()) / d.y();
            const Eigen::Vector3d p = o + t * d;
            if (p.x() >= kGroundMinX && p.x() <= kGroundMaxX && p.z() >= 0.0 && p.z() <= kWallHeight)
                take(t, SceneObject::Wall, Eigen::Vector3d::UnitY());
        }
        // |o + t d - c|^2 = r^2: the smaller root in range is the first hit.
        const Eigen::Vector3d center(kSphereCenter[0], kSphereCenter[1], kSphereCenter[2]);
        const Eigen::Vector3d oc = o - center;
        const double a = d.squaredNorm(), b = oc.dot(d), c = oc.squaredNorm() - kSphereRadius * kSphereRadius;
        const double disc = b * b - a * c;
        if (disc >= 0.0) {
            const double sq = std::sqrt(disc);
            const double t0 = (-b - sq) / a, t1 = (-b + sq) / a;
            const double t = t0 >= t_min ? t0 : t1;
            take(t, SceneObject::Sphere, (o + t * d - center).normalized());
        }
        const Eigen::Vector3d inv_d = d.cwiseInverse();
        double t_bunny = h.t;
        Eigen::Vector3d n_bunny;
        if (bunny_.intersect(o, d, inv_d, t_min, t_bunny, n_bunny))
            take(t_bunny, SceneObject::Bunny, n_bunny.normalized());
        if (h.object == SceneObject::Background) {
            h.t = std::numeric_limits<double>::infinity();
        } else if (h.normal.dot(d) > 0.0) {
            h.normal = -h.normal;
        }
        return h;
    }

private:
    TriangleBvh bunny_;
};

// ---------------------------------------------------------------------------------------------
// Cameras and rendering.

const Eigen::Vector3d kLookAt(0.25, 0.1, 0.35);
constexpr double kArcRadius = 2.6, kArcHeight = 1.3;
constexpr double kArcFrom = -160.0, kArcTo = -20.0;  // degrees

// The camera at arc position u in [0, 1].
Camera arc_camera(double u, const SimulatorOptions& o) {
    const double phi = (kArcFrom + (kArcTo - kArcFrom) * u) * kPi / 180.0;
    const Eigen::Vector3d eye(kLookAt.x() + kArcRadius * std::cos(phi),
                              kLookAt.y() + kArcRadius * std::sin(phi), kArcHeight);
    return Camera::look_at(eye, kLookAt, Eigen::Vector3d::UnitZ(), o.fov_y, o.width, o.height, 0.01, 100.0);
}

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
class Rng {
public:
    explicit Rng(std::uint64_t seed) : engine_(seed) {}
    double uniform() { return to_unit(engine_()); }  // [0, 1)
    double normal() {                                // Box-Muller, cosine branch
        const double u1 = 1.0 - uniform();           // (0, 1]
        const double u2 = uniform();
        return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
    }

private:
    std::mt19937_64 engine_;
};

}  // namespace

// -------------------------------------------------------------------------------------------------

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

open3d::geometry::TriangleMesh bunny_mesh() {
    const Mesh& b = bunny();
    open3d::geometry::TriangleMesh mesh;
    mesh.vertices_.resize(b.vertices.size() / 3);
    for (std::size_t i = 0; i < mesh.vertices_.size(); ++i)
        mesh.vertices_[i] = Eigen::Map<const Eigen::Vector3f>(&b.vertices[3 * i]).cast<double>();
    mesh.triangles_.resize(b.triangles.size() / 3);
    for (std::size_t f = 0; f < mesh.triangles_.size(); ++f)
        mesh.triangles_[f] = Eigen::Vector3i(int(b.triangles[3 * f]), int(b.triangles[3 * f + 1]),
                                             int(b.triangles[3 * f + 2]));
    return mesh;
}

std::vector<Camera> input_cameras(const SimulatorOptions& o) {
    o.validate();
    std::vector<Camera> cams;
    for (int i = 0; i < o.views; ++i)
        cams.push_back(arc_camera(o.views == 1 ? 0.5 : double(i) / (o.views - 1), o));
    return cams;
}

std::vector<Camera> target_cameras(const SimulatorOptions& o) {
    o.validate();
    std::vector<Camera> cams;
    for (int j = 0; j < o.target_views; ++j) {
        const int g = std::min(o.views - 2, static_cast<int>(std::floor((j + 0.5) * (o.views - 1) / o.target_views)));
        cams.push_back(arc_camera((g + 0.5) / (o.views - 1), o));
    }
    return cams;
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
