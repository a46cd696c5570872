// Assist-View conditioning: every view attends once to the tokens of its assist views
// (AVSplat's gated cross-attention).
//
// For view s with assists A(s) = [t_1, ..., t_K] (selection order) and tokens X_s (P x C):
//   Q = X_s Wq + bq,  K = [X_t Wk + bk]_{t in A(s)},  V = [X_t Wv + bv]_{t in A(s)}   (K P x C,
//   the assists' tokens concatenated in selection order); weights are C x C row-vector maps
//   (x -> x W), biases length C (zero when absent).
//   Per head h (channels h d .. h d + d - 1, d = C / heads):
//     O_h = softmax(Q_h K_h^T / sqrt(d)) V_h, softmax over each row, the row maximum subtracted.
//   C_s = [O_1 ... O_heads] Wo + bo;  output X_s + gate C_s.
// A view with no assists (K = 0) is passed through: output X_s.
//
// Numerics: the GEMMs (Eigen) run in the chosen precision; in float32 the softmax exponentials
// are float32 (Eigen's vectorised exp) and each row's normaliser is summed in float64.
// On x86-64 CPUs with AVX2 and FMA the float32 path runs kernels built for x86-64-v3 (chosen at
// run time), so its last bits differ from those on older CPUs; never with the thread count.
// Parallel over (view, block of 128 query rows) with OpenMP; the blocks are fixed, so the result
// does not depend on the thread count. Memory: besides input and output, K and V of every view
// that is an assist (2 S P C values of the precision) and per thread a 128 x K P block of logits.
#pragma once

#include "avsplat/core/precision.h"

#include <cstdint>

namespace avsplat {

struct ConditionWeights {
    /// C x C row-major, x -> x W. Required.
    const float* wq = nullptr;
    const float* wk = nullptr;
    const float* wv = nullptr;
    const float* wo = nullptr;
    /// Length C, or null for zero.
    const float* bq = nullptr;
    const float* bk = nullptr;
    const float* bv = nullptr;
    const float* bo = nullptr;
};

struct ConditionOptions {
    /// Attention heads (>= 1, dividing C).
    int heads = 1;
    /// Scale of the cross-attention output (finite).
    double gate = 1.0;
    Precision precision = Precision::Float32;
};

/// Conditions the tokens of every view on its assists' tokens.
///   tokens   S x P x C float32 row-major
///   assists  S x K view indices in [0, S) (e.g. AssistSelection::assists); K >= 0
///   out      S x P x C float32, written (must not overlap tokens)
/// Throws std::invalid_argument for bad dimensions or options (heads not dividing C, a
/// non-finite gate), an assist index out of range ("assists[s, j] = 9: ..."), or a non-finite
/// token, weight or bias (naming it and its index).
void condition_tokens(const float* tokens, int views, int tokens_per_view, int channels,
                      const std::int64_t* assists, int assists_per_view, const ConditionWeights& weights,
                      const ConditionOptions& options, float* out);

}  // namespace avsplat
