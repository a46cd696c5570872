// Private: ray casting against the default scene, in double precision.
#pragma once

#include "avsplat/sim/simulator.h"
#include "sim/bunny_mesh.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <utility>
#include <vector>

namespace avsplat::sim {

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

}  // namespace avsplat::sim
