// The weight functions of voxel fusion, the public names of a choice FusionParams makes (the
// confidence mapping is the core's, avsplat/core/confidence.h). The maths behind them is
// private (lib/src/fusion/voxel_weights.h).
#pragma once

#include "avsplat/core/confidence.h"

namespace avsplat {

/// Normalisation of the tempered logits z_i = l_i / tau into weights.
///   Softmax    w_i = exp(z_i - max z) / sum_j exp(z_j - max z)
///   Sparsemax  Euclidean projection of z onto the simplex (Martins & Astudillo 2016): weights
///              of samples more than one temperature-scaled unit below the leaders become 0.
enum class WeightFunction { Softmax, Sparsemax };

}  // namespace avsplat
