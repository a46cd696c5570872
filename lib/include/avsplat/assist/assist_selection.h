// Assist-View selection on per-view tokens (AVSplat, supplement Algorithm 1, with the choices the
// paper leaves open fixed in this header): before global attention, each view picks a small,
// relevant and diverse set of assist views by greedy coverage of its subsampled tokens.
//
// Definitions (X_s: the P x C tokens of view s; all of it in float64 except where noted):
//   descriptor  d_s = u / max(|u|, 1e-12), u = mean over p of X_s[p]; Sigma = clip(D D^T, -1, 1);
//               Delta = max(1 - Sigma, 0).
//   subsample   rows floor(j P / p_sub), j = 0..p_sub-1 (all rows if p_sub >= P), each divided
//               by max(|row|, 1e-12): Xh_s.
//   reliability v_s = mean over channels of the population variance over the rows of Xh_s;
//               q_s = v_s / max_t v_t (0 when every v is 0).
//   pool N(s)   the m' = min(m, S - 1) views t != s of largest Sigma[s, t], ties to the smaller
//               index, in that order.
//   support     sup_t[p] = max over rows j of Xh_s[p] . Xh_t[j] (one GEMM per pair (s, t), in
//               the selection's precision).
//   greedy      A = [N(s)[0]], c = sup_A0. While |A| < K = min(k, m'): every t in N(s) \ A scores
//               0.7 Sigma[s, t] + lambda_div min_{u in A} Delta[t, u]
//               + mean_p max(0, sup_t[p] - c[p]) + beta q_t;
//               the best joins A (ties to the smaller index) and c = max(c, sup_best).
//   jitter      with probability `jitter` per view the last assist is replaced by a member of
//               N(s) \ A drawn uniformly (nothing happens when N(s) \ A is empty). The draws of
//               view s are r_i = mix(seed + (2 s + i + 1) * 0x9E3779B97F4A7C15), i = 0, 1, with
//               mix the splitmix64 finaliser: replace when (r_0 >> 11) * 2^-53 < jitter, and take
//               the member floor((r_1 >> 11) * 2^-53 * n) of the n members of N(s) \ A in
//               increasing index order. So results depend on (seed, s) only, never on threads.
//   scores      the winning score of each pick. The first assist is chosen by Sigma, not by a
//               score; its entry is 0.7 Sigma[s, t] + mean_p max(0, sup_t[p]) + beta q_t (the
//               score with no diversity term and nothing covered). A jittered last assist gets
//               the score it had at the last step.
#pragma once

#include "avsplat/core/precision.h"

#include <cstdint>
#include <vector>

namespace avsplat {

struct AssistOptions {
    /// Assists per view (>= 0); each view gets K = min(k, min(m, S - 1)).
    int k = 4;
    /// Pool size (>= 0): the views most similar by descriptor that greedy chooses from.
    int m = 8;
    /// Subsampled token rows per view (>= 1).
    int p_sub = 64;
    /// Weight of the diversity term (finite).
    double lambda_div = 0.3;
    /// Weight of the reliability term (finite).
    double beta = 0.1;
    /// Probability in [0, 1] of replacing the last assist by a random pool member.
    double jitter = 0.0;
    std::uint64_t seed = 0;
    /// Scalar of the support GEMMs (everything else is float64 either way).
    Precision precision = Precision::Float32;
};

struct AssistSelection {
    int views = 0;
    /// Assists per view: K = min(k, min(m, S - 1)).
    int per_view = 0;
    int channels = 0;
    /// S x K view indices, each row in selection order.
    std::vector<std::int64_t> assists;
    /// S x K winning scores (see the header comment for the first and a jittered last one).
    std::vector<float> scores;
    /// S x C unit-length (or zero) mean-token descriptors d_s.
    std::vector<float> descriptors;
    /// S normalised reliabilities q_s in [0, 1].
    std::vector<float> reliability;
};

/// Selects the assist views of every view.
///   tokens  S x P x C float32, row-major (view, token, channel); S >= 0, P >= 1, C >= 1
/// Throws std::invalid_argument for a bad dimension or option, and for a non-finite token,
/// naming it: "tokens[s, p, c] = nan" (the first in memory order).
/// Parallel over views (OpenMP); the result does not depend on the thread count.
AssistSelection select_assist_views(const float* tokens, int views, int tokens_per_view, int channels,
                                    const AssistOptions& options);

/// The paper's objective of an assist set A of view s (computed in float64, GEMMs included):
///   F(A) = mean_p max_{t in A} sup_t[p] + beta mean_{t in A} q_t
///          - lambda_div * mean over ordered pairs t != u in A of Sigma[t, u]
/// (the pair term is 0 when |A| = 1), with sup, q and Sigma as in select_assist_views. For
/// comparing greedy with exhaustive search on small S.
/// Throws std::invalid_argument for bad dimensions, s out of range, an empty A, a member out of
/// range, equal to s or repeated, a non-finite option, or a non-finite token.
double assist_objective(const float* tokens, int views, int tokens_per_view, int channels, int s,
                        const std::vector<std::int64_t>& assists, double beta, double lambda_div, int p_sub);

}  // namespace avsplat
