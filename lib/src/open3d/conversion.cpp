#include "avsplat/open3d/conversion.h"

#include "avsplat/core/sh.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

namespace core = open3d::core;

core::Tensor tensor(const float* data, std::size_t count, const core::SizeVector& shape) {
    // Tensor(init_vals, shape, dtype) copies; the SizeVector product must equal count.
    std::vector<float> v(data, data + count);
    return core::Tensor(std::move(v), shape, core::Float32);
}

// A C-contiguous float32 CPU copy of attribute `key` with `count` values per point.
std::vector<float> read_attr(const open3d::t::geometry::PointCloud& pcd, const std::string& key,
                             int64_t n, int64_t per_point) {
    if (!pcd.HasPointAttr(key))
        throw std::invalid_argument("from_open3d: missing point attribute '" + key + "'");
    core::Tensor t = pcd.GetPointAttr(key).To(core::Device("CPU:0")).To(core::Float32).Contiguous();
    if (t.GetShape().size() == 0 || t.GetShape()[0] != n || t.NumElements() != n * per_point)
        throw std::invalid_argument("from_open3d: attribute '" + key + "' has shape " +
                                    t.GetShape().ToString() + ", expected " + std::to_string(n) +
                                    " x " + std::to_string(per_point) + " values");
    const float* p = t.GetDataPtr<float>();
    return std::vector<float>(p, p + n * per_point);
}

float logit(float p) { return std::log(p) - std::log1p(-p); }
float sigmoid(float x) { return 1.f / (1.f + std::exp(-x)); }

}  // namespace

open3d::t::geometry::PointCloud to_open3d(const GaussianCloud& c) {
    validate(c);
    const int64_t n = static_cast<int64_t>(c.size());
    const int k = c.sh_coeffs();
    open3d::t::geometry::PointCloud pcd(core::Device("CPU:0"));
    pcd.SetPointPositions(tensor(c.means.data(), c.means.size(), {n, 3}));
    pcd.SetPointAttr("scale", tensor(c.scales.data(), c.scales.size(), {n, 3}));
    pcd.SetPointAttr("rot", tensor(c.rotations.data(), c.rotations.size(), {n, 4}));
    std::vector<float> op(c.size()), dc(3 * c.size()), rest;
    for (std::size_t i = 0; i < c.size(); ++i) op[i] = logit(c.opacities[i]);
    pcd.SetPointAttr("opacity", tensor(op.data(), op.size(), {n, 1}));
    if (k > 1) rest.resize(c.size() * (k - 1) * 3);
    for (std::size_t i = 0; i < c.size(); ++i) {
        const float* s = &c.sh[i * k * 3];
        std::copy_n(s, 3, &dc[3 * i]);
        if (k > 1) std::copy_n(s + 3, (k - 1) * 3, &rest[i * (k - 1) * 3]);
    }
    pcd.SetPointAttr("f_dc", tensor(dc.data(), dc.size(), {n, 3}));
    if (k > 1) pcd.SetPointAttr("f_rest", tensor(rest.data(), rest.size(), {n, k - 1, 3}));
    if (c.has_confidence()) pcd.SetPointAttr("confidence", tensor(c.confidence.data(), c.size(), {n, 1}));
    for (const auto& e : c.extras) pcd.SetPointAttr(e.name, tensor(e.values.data(), c.size(), {n, 1}));
    return pcd;
}

GaussianCloud from_open3d(const open3d::t::geometry::PointCloud& pcd) {
    if (!pcd.HasPointPositions()) throw std::invalid_argument("from_open3d: missing point attribute 'positions'");
    const int64_t n = pcd.GetPointPositions().GetShape()[0];
    int k = 1;
    if (pcd.HasPointAttr("f_rest")) {
        const auto shape = pcd.GetPointAttr("f_rest").GetShape();
        const int64_t rest = shape.NumElements() / std::max<int64_t>(n, 1);
        if (shape.size() < 2 || shape[0] != n || rest % 3 != 0 ||
            sh_degree_for_coeffs(static_cast<int>(rest / 3) + 1) < 0)
            throw std::invalid_argument("from_open3d: attribute 'f_rest' has shape " + shape.ToString() +
                                        ", expected {N, K-1, 3} with K in 4, 9, 16");
        k = static_cast<int>(rest / 3) + 1;
    }
    GaussianCloud c(static_cast<std::size_t>(n), sh_degree_for_coeffs(k));
    c.means = read_attr(pcd, "positions", n, 3);
    c.scales = read_attr(pcd, "scale", n, 3);
    c.rotations = read_attr(pcd, "rot", n, 4);
    const std::vector<float> op = read_attr(pcd, "opacity", n, 1);
    for (int64_t i = 0; i < n; ++i) c.opacities[i] = sigmoid(op[i]);
    const std::vector<float> dc = read_attr(pcd, "f_dc", n, 3);
    std::vector<float> rest;
    if (k > 1) rest = read_attr(pcd, "f_rest", n, (k - 1) * 3);
    for (int64_t i = 0; i < n; ++i) {
        float* s = &c.sh[i * k * 3];
        std::copy_n(&dc[3 * i], 3, s);
        if (k > 1) std::copy_n(&rest[i * (k - 1) * 3], (k - 1) * 3, s + 3);
    }
    // TensorMap is unordered: take extra channels in name order so the result is deterministic.
    std::vector<std::string> names;
    for (const auto& kv : pcd.GetPointAttr()) {
        static const char* known[] = {"positions", "scale", "rot", "opacity", "f_dc", "f_rest"};
        if (std::find(std::begin(known), std::end(known), kv.first) != std::end(known)) continue;
        if (kv.second.NumElements() == n) names.push_back(kv.first);
    }
    std::sort(names.begin(), names.end());
    for (const auto& name : names) {
        std::vector<float> v = read_attr(pcd, name, n, 1);
        if (name == "confidence") c.confidence = std::move(v);
        else c.extras.push_back({name, std::move(v)});
    }
    return c;
}

open3d::geometry::PointCloud to_open3d_legacy(const GaussianCloud& c) {
    validate(c);
    open3d::geometry::PointCloud pcd;
    pcd.points_.resize(c.size());
    pcd.colors_.resize(c.size());
    const int k = c.sh_coeffs();
    for (std::size_t i = 0; i < c.size(); ++i) {
        pcd.points_[i] = c.mean(i).cast<double>();
        for (int ch = 0; ch < 3; ++ch)
            pcd.colors_[i][ch] = std::clamp(sh::dc_to_color<double>(c.sh[i * k * 3 + ch]), 0.0, 1.0);
    }
    return pcd;
}

open3d::geometry::TriangleMesh to_open3d(const TriangleMesh& mesh) {
    open3d::geometry::TriangleMesh out;
    const std::size_t n = mesh.num_vertices();
    out.vertices_.resize(n);
    for (std::size_t i = 0; i < n; ++i)
        out.vertices_[i] = Eigen::Vector3d(mesh.vertices[3 * i], mesh.vertices[3 * i + 1], mesh.vertices[3 * i + 2]);
    out.triangles_.resize(mesh.num_triangles());
    for (std::size_t f = 0; f < out.triangles_.size(); ++f) {
        for (int c = 0; c < 3; ++c) {
            const std::int32_t v = mesh.triangles[3 * f + c];
            if (v < 0 || std::size_t(v) >= n)
                throw std::invalid_argument("TriangleMesh.triangles[" + std::to_string(f) + ", " + std::to_string(c) +
                                            "] = " + std::to_string(v) + ": not a vertex index");
            out.triangles_[f][c] = v;
        }
    }
    return out;
}

}  // namespace avsplat
