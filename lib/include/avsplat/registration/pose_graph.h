// A pose graph over similarity transforms: nodes are coordinate frames (chunk 0 fixed as the
// world), edges are measured relative similarities; the optimum spreads every measurement's
// error over the graph, so that loops close and a chain drifts no more than its measurements.
#pragma once

#include "avsplat/registration/similarity.h"

#include <vector>

namespace avsplat {

/// A measurement between frames a and b: x_a = measured(x_b), i.e. measured ~ T_a^-1 T_b for
/// the world-from-frame transforms T.
struct PoseGraphEdge {
    int a = 0;
    int b = 0;
    Similarity measured;
    /// Information of the measurement (> 0): the residual (rotation error in radians,
    /// translation error / length, log scale error) is weighted by sqrt(weight).
    double weight = 1.0;
    /// Length (> 0) in frame b's units that makes the translation error unitless.
    double length = 1.0;
};

struct PoseGraphResult {
    std::vector<Similarity> transforms;  ///< world from frame i; transforms[0] is the identity
    double initial_cost = 0.0;           ///< sum of weighted squared residuals at the start
    double final_cost = 0.0;             ///< ... and at the end
    int iterations = 0;                  ///< Levenberg-Marquardt iterations run
};

/// Minimises sum_e weight_e |r_e|^2, r_e = (log R_E, t_E / length_e, log s_E) for
/// E = measured_e^-1 T_a^-1 T_b, over T_1 .. T_{n-1} (T_0 = identity) by Levenberg-Marquardt on
/// the manifold SO(3) x R^3 x R_+ (rotations updated by right-multiplied exponentials, scales by
/// exp), with central-difference Jacobians and a dense normal-equation solve: cost O(iterations
/// (edges + (7n)^3)). `initial` (n transforms) is the start. Deterministic (no threads).
/// Throws std::invalid_argument for fewer than 1 node, an edge naming a node outside 0..n-1 or
/// a node twice, a weight or length that is not finite and > 0, or a graph in which some node is
/// not connected to node 0 (naming it).
PoseGraphResult optimize_pose_graph(const std::vector<PoseGraphEdge>& edges, const std::vector<Similarity>& initial,
                                    int max_iterations = 100);

}  // namespace avsplat
