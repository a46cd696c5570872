// Voxel fusion: one fused sample (a feature vector, or a Gaussian) per occupied voxel.
//
// Samples are grouped by SparseVoxelGrid (k = round(p / voxel_size)); each voxel's samples get
// weights from a policy and are averaged with them:
//   Mean       the plain average (AnySplat / VGGT voxelisation without confidence).
//   Softmax    softmax of the raw confidence at temperature 1 (AnySplat). The confidence
//              mapping does not change the weights, only the reliability diagnostic.
//   Occupancy  occupancy-guided fusion (AVSplat, supplement Algorithm 2; README,
//              "Occupancy-guided voxel fusion"): the mapped
//              logits l_i are divided by a per-voxel temperature tau_v that falls with the
//              occupancy n_v and with the voxel's reliability r_v, normalised by softmax or
//              sparsemax, optionally trimmed to the mass trim_mass, and renormalised.
// Without confidence every policy gives the plain average (all logits are 0, and trimming keeps
// or drops tied weights together), so Occupancy without confidence equals Mean.
//
// Numerics. Weights are computed in the scalar chosen by FusionParams::precision (float32 by
// default; float64 is the reference path the tests hold the default to); all sums over samples
// (positions, variances, features, weights) are accumulated in double, and each fused value is
// the weighted sum divided by the sum of the weights. Weights are always finite, >= 0 and sum to
// 1 (to rounding), for any finite confidence including +-1e30. A voxel with one sample is copied
// through bit for bit.
//
// Determinism. Within a voxel the samples are put in a canonical order before any arithmetic:
// by decreasing confidence when there is one, then by the bits of the position (x, y, z), of
// the confidence, and of the remaining fields (features; or opacity, scales, rotations, SH,
// extras), so results are bit-identical for any permutation of the input and any number of
// OpenMP threads. Where the method speaks of "trimming ties by input order", the order is this
// canonical one; as trimming keeps tied weights together, the order of ties never matters.
// (Ordered by confidence, the weights decrease along the voxel, so trimming needs no sort.)
//
// Diagnostics per voxel (VoxelDiagnostics) are computed for every policy; see the fields.
#pragma once

#include "avsplat/fusion/confidence.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/core/invalid_policy.h"
#include "avsplat/core/precision.h"
#include "avsplat/fusion/voxel_grid.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat {

enum class FusionPolicy { Mean, Softmax, Occupancy };

/// How fuse_gaussians combines the shapes (scale and rotation) of a voxel's Gaussians.
///   Average  weighted mean of the log-scales (a weighted geometric mean of the scales) and of
///            the unit quaternions after flipping each into the hemisphere of the voxel's
///            highest-weight quaternion, normalised.
///   Moment   weighted moment matching: Sigma = sum_i w_i (Sigma_i + (mu_i - mu)(mu_i - mu)^T),
///            decomposed into scales sqrt(eigenvalues), increasing, and the rotation of the
///            eigenvectors (determinant +1). The fused Gaussian covers its members' spread.
enum class ShapeMode { Average, Moment };

// Precision (float32 fast path / float64 reference) is defined in precision.h.

/// Fusion settings. The names match the Python keyword arguments. The occupancy knobs and their
/// defaults are the paper's (tau0, alpha, n_ref, tau_min, tau_max, b_geo, trim_mass) or fixed by
/// this library where the paper leaves them open (b_conf, k_rel, eps); the mean and softmax
/// policies ignore them.
struct FusionParams {
    FusionPolicy policy = FusionPolicy::Occupancy;
    double tau0 = 0.7;        ///< base temperature, > 0
    double alpha = 0.5;       ///< occupancy exponent, >= 0
    double n_ref = 8.0;       ///< reference occupancy, > 0
    double tau_min = 0.15;    ///< temperature clip range, 0 < tau_min <= tau_max
    double tau_max = 2.0;
    double b_conf = 1.0;      ///< weight of the mean confidence probability in r_v, >= 0
    double b_geo = 2.0;       ///< weight of the geometric consistency g_v in r_v, >= 0
    double k_rel = 1.0;       ///< how much unreliability raises the temperature, >= 0
    double eps = 1e-6;        ///< floor in g_v, r_v and the occupancy ratio, >= 0
    double trim_mass = 0.8;   ///< keep the weight mass trim_mass; 0 (or 1) turns trimming off
    WeightFunction weights = WeightFunction::Softmax;
    ConfidenceMapping confidence_mapping = ConfidenceMapping::Logit;
    ShapeMode shape = ShapeMode::Average;  ///< fuse_gaussians only
    InvalidPolicy on_invalid = InvalidPolicy::Raise;
    Precision precision = Precision::Float32;
};

/// Throws std::invalid_argument naming the first bad field, e.g. "FusionParams.tau_min: ...".
void validate(const FusionParams& params);

/// Per-voxel diagnostics, M entries each, in voxel order.
struct VoxelDiagnostics {
    std::vector<std::int32_t> occupancy;  ///< n_v, samples in the voxel
    /// tau_v for Occupancy; 1 for Softmax; +inf for Mean (a softmax at infinite temperature).
    std::vector<float> temperature;
    std::vector<float> variance;     ///< sigma_v^2 = E|p - mu_v|^2 (sum of per-axis variances)
    std::vector<float> reliability;  ///< r_v in [0, 1] (q = 0.5 without confidence)
    std::vector<std::int32_t> kept;  ///< samples with a non-zero final weight
    std::vector<float> entropy;      ///< -sum w log w of the final weights, nats

    /// Appends the voxels of `other` after these (the blocks of a FusionStream, in key order).
    void append(const VoxelDiagnostics& other);
};

/// Result of fuse_voxels. M = number of occupied voxels, in SparseVoxelGrid order.
struct FeatureFusionResult {
    std::vector<float> positions;            ///< M x 3 weighted mean positions
    std::vector<float> features;             ///< M x C weighted mean features
    int channels = 0;                        ///< C
    std::vector<std::int32_t> voxel_coords;  ///< M x 3 voxel keys
    std::vector<std::int32_t> sample_voxel;  ///< N: voxel of each input sample, -1 if dropped
    VoxelDiagnostics diagnostics;
    std::size_t dropped = 0;                 ///< invalid samples dropped (on_invalid = Drop)
    std::size_t size() const noexcept { return voxel_coords.size() / 3; }
};

/// Result of fuse_gaussians: the fused cloud (M Gaussians) and the same bookkeeping.
struct GaussianFusionResult {
    GaussianCloud cloud;
    std::vector<std::int32_t> voxel_coords;
    std::vector<std::int32_t> sample_voxel;
    VoxelDiagnostics diagnostics;
    std::size_t dropped = 0;
    std::size_t size() const noexcept { return cloud.size(); }
};

/// Raw-feature fusion (AnySplat, AVSplat): n samples with a position, C float channels and an
/// optional confidence.
///   positions   n x 3 float32, row-major
///   features    n x C float32, row-major (C >= 0; may be null when C == 0)
///   voxel_size  > 0, finite
///   confidence  n float32, or null (then l_i = 0 and q_i = 0.5 for every sample)
/// Invalid samples (NaN/Inf in positions, features or confidence; a confidence outside the
/// domain of params.confidence_mapping) throw std::invalid_argument naming the field and the
/// first bad index ("features[12, 3] = nan ..."), or are dropped and counted when
/// params.on_invalid is Drop. A key that does not fit int32 always throws.
/// Progress (avsplat/core/progress.h): samples of n, at the start and the end.
FeatureFusionResult fuse_voxels(const float* positions, std::size_t n, const float* features,
                                int channels, double voxel_size, const float* confidence = nullptr,
                                const FusionParams& params = {});

/// Gaussian fusion: one Gaussian per occupied voxel of the means. Means, SH coefficients,
/// extra channels and the confidence (its raw value) are weighted means; the opacity is the
/// weighted mean of the opacities in [0, 1]; the shape follows params.shape. The weights use
/// cloud.confidence when present. The fused rotations are unit quaternions with w >= 0, except
/// in voxels with one Gaussian, which is copied as it is. Invalid Gaussians (what validate()
/// rejects, or a confidence outside its mapping's domain) throw std::invalid_argument or are
/// dropped (params.on_invalid); shape errors always throw.
/// Progress (avsplat/core/progress.h): samples fused of cloud.size(), up to 64 reports.
GaussianFusionResult fuse_gaussians(const GaussianCloud& cloud, double voxel_size,
                                    const FusionParams& params = {});

}  // namespace avsplat
