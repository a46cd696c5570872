// Test-only reference versions of the voxel weight maths (lib/src/fusion/voxel_weights.h):
// the plain forms that the library's fused, step-by-step paths are held to. They use the
// library's own building blocks (exp_nonpositive, sort_descending, normalise_with_entropy), so a
// test compares two compositions of them, not two copies of one formula.
#pragma once

#include "fusion/voxel_weights.h"

namespace avsplat::fusion_weights {

/// Temperature tau = clip(tau0 * max(n / n_ref, eps)^(-alpha) / (1 + k_rel * (1 - r)),
/// tau_min, tau_max): crowded, reliable voxels get sharper weights.
template <class T>
AVSPLAT_HD T temperature(long long n, T r, T tau0, T alpha, T n_ref, T tau_min, T tau_max, T k_rel,
                         T eps) {
    return temperature_from_factor<T>(temperature_factor<T>(n, tau0, alpha, n_ref, eps), r, tau_min, tau_max,
                                      k_rel);
}

/// Softmax weights of the logits l[0..n) at temperature tau > 0: w_i = exp((l_i - max l) / tau)
/// / sum. The shifted logits are <= 0 and never NaN (l is finite), so every weight is finite
/// and in [0, 1], the largest logit gets exp(0) = 1 and the sum (in double) is >= 1.
template <class T>
AVSPLAT_HD void softmax_weights(const T* l, long long n, T tau, T* w) {
    T lmax = l[0];
    for (long long i = 1; i < n; ++i) lmax = l[i] > lmax ? l[i] : lmax;
    for (long long i = 0; i < n; ++i) w[i] = (l[i] - lmax) / tau;
    exp_nonpositive(w, n, w);
    double sum = 0.0;
    for (long long i = 0; i < n; ++i) sum += double(w[i]);
    const double inv = 1.0 / sum;
    for (long long i = 0; i < n; ++i) w[i] = T(double(w[i]) * inv);
}

/// The rest of softmax_trimmed once the exponentials are known: w holds e_i = exp(z_i) on entry
/// and the trimmed, normalised weights on return; z holds the z_i of softmax_logits; scratch
/// holds n values. Returns the number of non-zero weights and stores the entropy.
template <class T>
AVSPLAT_HD long long softmax_normalise(T* w, const T* z, long long n, double m, T* scratch, T* entropy) {
    double total = 0.0;
    for (long long i = 0; i < n; ++i) total += double(w[i]);
    if (m > 0.0 && m < 1.0) {
        const double mass_kept = m * total;
        for (long long i = 0; i < n; ++i) scratch[i] = w[i];
        sort_descending(scratch, n);
        double above = 0.0;
        long long k = 0;
        while (k < n && scratch[k] > T(0) && above < mass_kept) above += double(scratch[k++]);
        const T cut = scratch[k - 1];
        for (long long i = 0; i < n; ++i) w[i] = w[i] >= cut ? w[i] : T(0);
        total = 0.0;
        for (long long i = 0; i < n; ++i) total += double(w[i]);
    }
    return normalise_with_entropy(w, z, n, total, entropy);
}

/// Softmax of the logits l[0..n) at temperature tau > 0, trimmed to the mass m, with its entropy:
/// what softmax_weights, trim_weights and weight_entropy compute in turn, in one pass over the
/// exponentials e_i = exp(z_i), z_i = (l_i - max l) / tau, with S = sum e:
///   - sample i is kept when the mass of the e_j > e_i is below m * S (so ties are kept or
///     dropped together, and the leader, with e = 1, always stays); m <= 0 or m >= 1 keeps all;
///   - w_i = e_i / K for kept samples, K = sum of the kept e, else 0;
///   - the entropy is sum_{w_i > 0} w_i (log K - z_i), with no logarithm per sample.
/// The cut is found on a sorted copy of e (softmax_normalise_sorted skips the sort when the
/// logits come in decreasing order).
/// z and scratch hold n values (z receives z_i). Returns the number of non-zero weights.
/// softmax_logits, exp_nonpositive and softmax_normalise are its three steps, for callers that
/// run each step over many voxels at once.
template <class T>
AVSPLAT_HD long long softmax_trimmed(const T* l, long long n, T tau, double m, T* w, T* z, T* scratch,
                                     T* entropy) {
    softmax_logits(l, n, tau, z);
    exp_nonpositive(z, n, w);
    return softmax_normalise(w, z, n, m, scratch, entropy);
}

}  // namespace avsplat::fusion_weights
