// How a per-sample confidence is read: the mapping that fusion (FusionParams) and point maps
// (PointMapOptions) share. The maths is private (lib/src/core/confidence_mapping.h).
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

}  // namespace avsplat
