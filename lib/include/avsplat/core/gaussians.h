// GaussianCloud: a set of 3D Gaussians as structure-of-arrays float32 buffers.
//
// Conventions (as gsplat and the INRIA 3DGS code):
//   means      N x 3   world position
//   scales     N x 3   linear axis lengths (not log)
//   rotations  N x 4   quaternion (w, x, y, z); need not be unit, must not be zero
//   opacities  N       in [0, 1] (not a logit)
//   sh         N x K x 3, K = (d + 1)^2 for SH degree d in 0..3, degree 0 first
//   confidence N or empty (absent)
//   extras     named float channels of N values each (e.g. from PLY properties we do not interpret)
//
// All arrays are row-major and contiguous. The members are public, as in Open3D's geometry
// types; `validate` checks that they are consistent and finite before a kernel relies on it.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace avsplat {

/// Coefficients per colour channel for SH degree d: (d + 1)^2.
constexpr int sh_coeffs_for_degree(int degree) { return (degree + 1) * (degree + 1); }

/// The SH degree whose coefficient count is k, or -1 when k is not 1, 4, 9 or 16.
int sh_degree_for_coeffs(int k);

/// Highest SH degree avsplat stores, renders and writes.
constexpr int kMaxShDegree = 3;

/// A named per-Gaussian float channel (N values).
struct NamedChannel {
    std::string name;
    std::vector<float> values;
};

class GaussianCloud {
public:
    GaussianCloud() = default;

    /// n Gaussians of SH degree `sh_degree`: means 0, scales 1, identity rotations,
    /// opacity 1, SH 0, no confidence. Throws std::invalid_argument for a degree outside 0..3.
    GaussianCloud(std::size_t n, int sh_degree);

    /// Copies n Gaussians from contiguous row-major float32 arrays with the shapes above.
    /// `confidence` may be null (absent). Does not validate values; call `validate`.
    static GaussianCloud from_arrays(std::size_t n, int sh_degree, const float* means,
                                     const float* scales, const float* rotations,
                                     const float* opacities, const float* sh,
                                     const float* confidence = nullptr);

    std::size_t size() const noexcept { return opacities.size(); }
    bool empty() const noexcept { return opacities.empty(); }
    /// K = (sh_degree + 1)^2 coefficients per colour channel.
    int sh_coeffs() const noexcept { return sh_coeffs_for_degree(sh_degree); }
    bool has_confidence() const noexcept { return !confidence.empty(); }

    Eigen::Map<const Eigen::Vector3f> mean(std::size_t i) const { return Eigen::Map<const Eigen::Vector3f>(&means[3 * i]); }
    Eigen::Map<const Eigen::Vector3f> scale(std::size_t i) const { return Eigen::Map<const Eigen::Vector3f>(&scales[3 * i]); }
    /// Quaternion of Gaussian i as stored (w, x, y, z), not normalised.
    Eigen::Map<const Eigen::Vector4f> rotation(std::size_t i) const { return Eigen::Map<const Eigen::Vector4f>(&rotations[4 * i]); }

    /// Covariance R S S^T R^T of Gaussian i in double precision (the quaternion is normalised).
    Eigen::Matrix3d covariance(std::size_t i) const;

    /// Axis-aligned bounds of the means: {min, max}. Throws std::invalid_argument when empty.
    std::pair<Eigen::Vector3f, Eigen::Vector3f> bounding_box() const;

    /// The extra channel called `name`, or nullptr.
    const NamedChannel* find_extra(const std::string& name) const;
    /// Adds or replaces an extra channel. Replacing copies into the channel's storage (pointers
    /// into it stay valid). Throws std::invalid_argument when values.size() != size().
    void set_extra(const std::string& name, std::vector<float> values);

    std::vector<float> means;
    std::vector<float> scales;
    std::vector<float> rotations;
    std::vector<float> opacities;
    std::vector<float> sh;
    std::vector<float> confidence;
    std::vector<NamedChannel> extras;
    int sh_degree = 0;
    /// The Gaussians were trained for antialiased rasterisation (Mip-Splatting's 2D filter,
    /// gsplat's rasterize_mode="antialiased"): render them with RenderOptions::antialiased =
    /// cloud.antialiased. SPZ files carry it (header flag); other formats do not store it.
    /// `select` keeps it; `concatenate` sets it when every cloud has it.
    bool antialiased = false;
};

/// Checks shapes and values. Throws std::invalid_argument naming the field and the first bad
/// index, e.g. "GaussianCloud.rotations[12]: zero-norm quaternion". Checks, in order: SH degree
/// in 0..3; array sizes against N; finite values everywhere; scales >= 0; quaternion norm > 0;
/// opacity in [0, 1].
void validate(const GaussianCloud& cloud);

/// What `sanitize` dropped. Each dropped Gaussian is counted once, under the first reason in
/// the order of the fields below.
struct SanitizeReport {
    std::size_t kept = 0;
    std::size_t dropped = 0;
    std::size_t non_finite = 0;       ///< NaN or Inf in any field
    std::size_t negative_scale = 0;
    std::size_t zero_rotation = 0;    ///< quaternion of zero norm
    std::size_t opacity_range = 0;    ///< opacity outside [0, 1]
    /// One line, e.g. "kept 998, dropped 2 (non_finite 1, negative_scale 1)".
    std::string summary() const;
};

/// Drops the Gaussians that `validate` would reject for their values, keeping the order of the
/// rest. Shape errors are not droppable and still throw std::invalid_argument. The arrays are
/// compacted in place and never reallocated, so pointers into them (numpy views, a call running
/// on another thread) stay valid; what they see past the new size is unspecified.
SanitizeReport sanitize(GaussianCloud& cloud);

/// The Gaussians at `indices`, in that order (repeats allowed). Throws std::out_of_range naming
/// the first bad position.
GaussianCloud select(const GaussianCloud& cloud, const std::vector<std::size_t>& indices);

/// The Gaussians whose mask entry is non-zero. Throws std::invalid_argument on a size mismatch.
GaussianCloud select_mask(const GaussianCloud& cloud, const std::vector<std::uint8_t>& mask);

/// All Gaussians of `clouds`, in order. SH of lower degree is zero-padded to the highest degree.
/// Confidence and extra channels must be present in all clouds or in none (same names), else
/// std::invalid_argument names the first cloud that differs.
GaussianCloud concatenate(const std::vector<GaussianCloud>& clouds);

}  // namespace avsplat
