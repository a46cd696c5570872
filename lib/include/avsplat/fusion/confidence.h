// The confidence mappings and weight functions of voxel fusion: the public names of the
// choices that FusionParams and PointMapOptions make. The maths behind them is private
// (lib/src/fusion/voxel_weights.h).
#pragma once

namespace avsplat {

/// How a raw confidence c becomes a logit l (the softmax input) and a probability q (for the
/// reliability term). Every mapping clamps l to [-FLT_MAX, FLT_MAX] so that it is finite.
///   Logit        any finite c:   l = c,                  q = sigmoid(c)       (default)
///   Probability  c in [0, 1]:    l = log(c) - log(1-c),  q = c
///   Positive     c >= 0 (the 1 + exp(x) confidences of VGGT / AnySplat heads):
///                                l = log(c),             q = c / (1 + c)
/// A confidence outside its mapping's domain, or NaN/Inf, is invalid.
enum class ConfidenceMapping { Logit, Probability, Positive };

/// Normalisation of the tempered logits z_i = l_i / tau into weights.
///   Softmax    w_i = exp(z_i - max z) / sum_j exp(z_j - max z)
///   Sparsemax  Euclidean projection of z onto the simplex (Martins & Astudillo 2016): weights
///              of samples more than one temperature-scaled unit below the leaders become 0.
enum class WeightFunction { Softmax, Sparsemax };

}  // namespace avsplat
