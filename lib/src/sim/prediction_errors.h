// Private: the simulator's error models that act on a view's pixels after ray casting (mixed
// pixels, uncertainty) and on all views together (head features, their noise, the confidence of
// a given informativeness); sim/simulator.h documents each model.
#pragma once

#include "avsplat/sim/simulator.h"

#include <Eigen/Core>

#include <vector>

namespace avsplat::sim {

/// Mixed pixels: the colours (H x W x 3) of the pixels with depth > 0 (H x W, true camera-space
/// depth, 0 for background) become (1 - beta) c + beta c_other, beta the fraction of the pixels
/// within `radius` (Euclidean, inside the image) that lie on another surface, c_other their mean
/// colour. radius <= 0 leaves the colours alone. Returns beta per pixel (0 for background).
std::vector<float> mix_pixels(std::vector<float>& colors, const std::vector<float>& depth, const Camera& cam,
                              double radius);

/// The uncertainty u in [1, 5] of each pixel of a view (0 for background): 1 + far + grazing +
/// textureless + edge (sim/simulator.h). depth: H x W true depth (0: background); cos: H x W
/// |cos| between ray and normal; reference: H x W x 3 the true diffuse colours.
std::vector<float> uncertainty(const std::vector<float>& depth, const std::vector<float>& cos,
                               const std::vector<float>& reference, const Camera& cam);

/// Head features, their noise and the confidence model, for all views of `P` at once: fills
/// P.features, P.feature_layout, P.appearance_error and P.confidence_spearman, and replaces
/// P.confidence when o.confidence_rho is set. Needs P's points, colours, confidence, normals,
/// valid, cameras, true_error and uncertainty; depth (S x H x W, true depth) and reference
/// (S x H x W x 3, the true diffuse colours) come from the ray casting.
void head_features(Predictions& P, const SimulatorOptions& o, const std::vector<float>& depth,
                   const std::vector<float>& reference);

/// Spearman's rank correlation of a and b (ties get their mean rank), in double; NaN for fewer
/// than 2 values or a constant input.
double spearman(const std::vector<double>& a, const std::vector<double>& b);

/// The confidence model of a given informativeness: returns `values` (the confidences of the
/// default model, any order) handed out so that their Spearman correlation with `score` (higher
/// = better) is rho in expectation (Gaussian copula, sim/simulator.h). noise: one N(0, 1) draw
/// per entry. Deterministic: ties are broken by index.
std::vector<double> confidence_by_rank(const std::vector<double>& values, const std::vector<double>& score,
                                       const std::vector<double>& noise, double rho);

}  // namespace avsplat::sim
