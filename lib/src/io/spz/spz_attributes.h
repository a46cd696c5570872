// Private: SPZ's quantisation of the attribute blocks (the container is spz_container.h), and the
// axis change between an SPZ file's axes and avsplat's.
#pragma once

#include "io/spz/spz_container.h"

#include "avsplat/core/gaussians.h"
#include "avsplat/io/spz.h"

#include <array>

namespace avsplat::io::spz {

/// The reference's colour scale: the colour byte is round(255 * (0.15 * dc + 0.5)).
constexpr double kColorScale = 0.15;

/// The change between axes `axes` (one of the eight sign conventions) and avsplat's RDF: every
/// one is diagonal, F = diag(sx, sy, sz) with s = +1 where the axis agrees (Right, Down, Front)
/// and -1 where it does not, and is its own inverse, so one table serves reading and writing.
/// Under p' = F p a Gaussian's rotation R becomes F R F, which for the quaternion is a sign on
/// x, y, z (sy sz, sx sz, sx sy; w keeps its sign, also when F is a reflection); an SH
/// coefficient c of basis function Y becomes s c with Y(F d) = s Y(d), s the product of the signs
/// of the axes that Y is odd in. RUB <-> RDF is the 180-degree rotation about x: F = diag(1, -1, -1).
/// The general `transform` (core/transform.h) (SH rotated by Wigner-D) is the same map for these F.
struct AxisFlip {
    std::array<float, 3> position{};
    std::array<float, 3> quaternion_xyz{};
    std::array<float, 15> sh{};  ///< per coefficient of bands 1..3, m = -l..l (the DC term keeps its sign)
};
AxisFlip axis_flip(SpzCoordinateSystem axes);

/// Quantises `cloud` (validated by the caller) into the blocks of `options.version`, in the axes
/// `options.coordinate_system`. Throws std::invalid_argument for a coordinate that does not fit.
PackedSpz pack_attributes(const GaussianCloud& cloud, const SpzWriteOptions& options);

/// Decodes the blocks into a cloud in avsplat's axes, taking the file's data to be in `axes`.
GaussianCloud unpack_attributes(const PackedSpz& packed, SpzCoordinateSystem axes);

}  // namespace avsplat::io::spz
