// Raw Gaussian-head features -> Gaussians: the decoder that runs after raw-feature fusion.
//
// AnySplat and AVSplat fuse the raw outputs of their Gaussian head (pre-activation features) per
// voxel and decode Gaussians only after fusion. fuse_voxels (fusion.h) fuses such feature vectors;
// decode_gaussians turns the fused vectors (or per-pixel ones) into a GaussianCloud with the
// activations AnySplat uses:
//   opacity   sigmoid(l)                       from one channel, the opacity logit
//   scale     exp(s_k), k = 0..2               from three channels of log axis lengths
//   rotation  q / |q|                          from four channels (w, x, y, z), any non-zero length
//   SH        as is                            3 (d + 1)^2 channels laid out [K][3], degree 0 first
// encode_gaussians is the inverse (logit, log, normalised quaternion, SH), for making raw features
// from Gaussians (the simulator does, and a test can round-trip).
//
// Averaging raw features is not averaging Gaussians: the fused opacity is the sigmoid of the mean
// logit (not the mean opacity), the fused scale the geometric mean of the scales, the fused
// rotation the normalised mean of the raw quaternions (which can cancel for opposite signs).
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <vector>

namespace avsplat {

/// Where each Gaussian field sits in a raw feature vector of C channels: the first channel of
/// each field (opacity 1 channel, scale 3, rotation 4, SH 3 (sh_degree + 1)^2). The default is
/// the packed layout [opacity logit | log scale x3 | quaternion w,x,y,z | SH], C = 8 + 3 K.
/// Channels that no field uses are ignored; fields may not overlap.
struct FeatureLayout {
    int opacity = 0;
    int scale = 1;
    int rotation = 4;
    int sh = 8;
    int sh_degree = 0;  ///< 0..3

    /// One past the last channel any field uses: the smallest C the layout fits.
    int channels() const noexcept;
    /// Throws std::invalid_argument ("FeatureLayout.<field>: ...") for a negative offset, an SH
    /// degree outside 0..3, overlapping fields, or (channels >= 0) a field beyond `channels`.
    void validate(int channels = -1) const;
};

/// Decodes n raw feature vectors into n Gaussians (activations above), in input order.
///   positions   n x 3 float32 (the means, copied)
///   features    n x C float32, row-major, C >= layout.channels()
///   confidence  n float32 copied into the cloud's confidence channel, or null
/// The activations run in double and round once to float32; sigmoid is evaluated stably for
/// any finite logit (a logit of -1e30 gives opacity 0). Throws std::invalid_argument naming the
/// first bad sample for: a non-finite position, feature or confidence ("features[i, c]"); a log
/// scale whose exponential overflows float32 (> 88.72); a quaternion of zero length. n = 0
/// gives an empty cloud of degree layout.sh_degree.
GaussianCloud decode_gaussians(const float* positions, std::size_t n, const float* features, int channels,
                               const FeatureLayout& layout = {}, const float* confidence = nullptr);

/// The inverse of decode_gaussians: N x layout.channels() raw features of `cloud` (row-major;
/// unused channels 0). Opacities are clamped to [1e-6, 1 - 1e-6] before the logit and scales
/// floored at FLT_MIN before the logarithm, so every feature is finite; quaternions are
/// normalised. Throws std::invalid_argument when cloud.sh_degree != layout.sh_degree or for an
/// invalid layout.
std::vector<float> encode_gaussians(const GaussianCloud& cloud, const FeatureLayout& layout = {});

}  // namespace avsplat
