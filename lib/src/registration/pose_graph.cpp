// Levenberg-Marquardt over SO(3) x R^3 x R_+ for the similarity pose graph.
#include "avsplat/registration/pose_graph.h"

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

namespace {

using Vector7d = Eigen::Matrix<double, 7, 1>;

Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w) {
    const double angle = w.norm();
    if (angle < 1e-300) return Eigen::Matrix3d::Identity();
    return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

Eigen::Vector3d log_so3(const Eigen::Matrix3d& R) {
    const Eigen::AngleAxisd aa(R);
    return aa.angle() * aa.axis();
}

// The node moved by a tangent step: R exp(w), t + v, s exp(sigma).
Similarity retract(const Similarity& T, const Vector7d& d) {
    Similarity r;
    r.rotation = T.rotation * exp_so3(d.head<3>());
    r.translation = T.translation + d.segment<3>(3);
    r.scale = T.scale * std::exp(d[6]);
    return r;
}

Vector7d edge_residual(const PoseGraphEdge& e, const Similarity& Ta, const Similarity& Tb) {
    const Similarity E = e.measured.inverse() * Ta.inverse() * Tb;
    Vector7d r;
    r.head<3>() = log_so3(E.rotation);
    r.segment<3>(3) = E.translation / e.length;
    r[6] = std::log(E.scale);
    return std::sqrt(e.weight) * r;
}

double total_cost(const std::vector<PoseGraphEdge>& edges, const std::vector<Similarity>& T) {
    double c = 0.0;
    for (const PoseGraphEdge& e : edges) c += edge_residual(e, T[e.a], T[e.b]).squaredNorm();
    return c;
}

}  // namespace

PoseGraphResult optimize_pose_graph(const std::vector<PoseGraphEdge>& edges, const std::vector<Similarity>& initial,
                                    int max_iterations) {
    const int n = static_cast<int>(initial.size());
    if (n < 1) throw std::invalid_argument("optimize_pose_graph: need at least one node");
    if (max_iterations < 0) throw std::invalid_argument("optimize_pose_graph: max_iterations must be >= 0");
    std::vector<std::vector<int>> adjacent(n);
    for (std::size_t k = 0; k < edges.size(); ++k) {
        const PoseGraphEdge& e = edges[k];
        const std::string at = "optimize_pose_graph: edge " + std::to_string(k);
        if (e.a < 0 || e.a >= n || e.b < 0 || e.b >= n || e.a == e.b)
            throw std::invalid_argument(at + " joins nodes " + std::to_string(e.a) + " and " + std::to_string(e.b) +
                                        " (must be two different nodes in 0.." + std::to_string(n - 1) + ")");
        if (!(std::isfinite(e.weight) && e.weight > 0.0)) throw std::invalid_argument(at + ": weight must be finite and > 0");
        if (!(std::isfinite(e.length) && e.length > 0.0)) throw std::invalid_argument(at + ": length must be finite and > 0");
        if (!(std::isfinite(e.measured.scale) && e.measured.scale > 0.0))
            throw std::invalid_argument(at + ": the measured scale must be finite and > 0");
        adjacent[e.a].push_back(e.b);
        adjacent[e.b].push_back(e.a);
    }
    std::vector<char> reached(n, 0);
    std::vector<int> queue{0};
    reached[0] = 1;
    for (std::size_t q = 0; q < queue.size(); ++q)
        for (int v : adjacent[queue[q]])
            if (!reached[v]) reached[v] = 1, queue.push_back(v);
    for (int i = 0; i < n; ++i)
        if (!reached[i]) throw std::invalid_argument("optimize_pose_graph: node " + std::to_string(i) +
                                                     " is not connected to node 0 by any edge");

    PoseGraphResult result;
    result.transforms = initial;
    result.transforms[0] = Similarity{};
    std::vector<Similarity>& T = result.transforms;
    double cost = total_cost(edges, T);
    result.initial_cost = cost;
    const int dim = 7 * (n - 1);
    if (dim == 0 || edges.empty()) {
        result.final_cost = cost;
        return result;
    }
    double lambda = 1e-4;
    constexpr double h = 1e-6;
    for (int it = 0; it < max_iterations; ++it) {
        Eigen::MatrixXd JtJ = Eigen::MatrixXd::Zero(dim, dim);
        Eigen::VectorXd Jtr = Eigen::VectorXd::Zero(dim);
        for (const PoseGraphEdge& e : edges) {
            const Vector7d r0 = edge_residual(e, T[e.a], T[e.b]);
            Eigen::Matrix<double, 7, 14> J = Eigen::Matrix<double, 7, 14>::Zero();
            for (int side = 0; side < 2; ++side) {
                const int node = side == 0 ? e.a : e.b;
                if (node == 0) continue;
                for (int j = 0; j < 7; ++j) {
                    Vector7d d = Vector7d::Zero();
                    d[j] = h;
                    const Similarity plus = retract(T[node], d), minus = retract(T[node], -d);
                    const Vector7d rp = side == 0 ? edge_residual(e, plus, T[e.b]) : edge_residual(e, T[e.a], plus);
                    const Vector7d rm = side == 0 ? edge_residual(e, minus, T[e.b]) : edge_residual(e, T[e.a], minus);
                    J.col(7 * side + j) = (rp - rm) / (2.0 * h);
                }
            }
            const int nodes[2] = {e.a, e.b};
            for (int s1 = 0; s1 < 2; ++s1) {
                if (nodes[s1] == 0) continue;
                const int o1 = 7 * (nodes[s1] - 1);
                Jtr.segment<7>(o1) += J.middleCols<7>(7 * s1).transpose() * r0;
                for (int s2 = 0; s2 < 2; ++s2) {
                    if (nodes[s2] == 0) continue;
                    const int o2 = 7 * (nodes[s2] - 1);
                    JtJ.block<7, 7>(o1, o2) += J.middleCols<7>(7 * s1).transpose() * J.middleCols<7>(7 * s2);
                }
            }
        }
        bool improved = false;
        for (int attempt = 0; attempt < 12 && !improved; ++attempt) {
            Eigen::MatrixXd A = JtJ;
            A.diagonal() += lambda * (JtJ.diagonal().array() + 1e-12).matrix();
            const Eigen::VectorXd step = A.ldlt().solve(-Jtr);
            std::vector<Similarity> trial = T;
            for (int i = 1; i < n; ++i) trial[i] = retract(T[i], step.segment<7>(7 * (i - 1)));
            const double trial_cost = total_cost(edges, trial);
            if (std::isfinite(trial_cost) && trial_cost < cost) {
                const double gain = cost - trial_cost;
                T = std::move(trial);
                cost = trial_cost;
                lambda = std::max(lambda / 10.0, 1e-12);
                improved = true;
                result.iterations = it + 1;
                if (gain <= 1e-14 * (1.0 + cost) || step.norm() < 1e-12) it = max_iterations;
            } else {
                lambda *= 10.0;
            }
        }
        if (!improved) break;
    }
    result.final_cost = cost;
    return result;
}

}  // namespace avsplat
