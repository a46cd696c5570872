// The ".splat" format of the antimatter15 WebGL viewer (and the viewers derived from it).
//
// 32 bytes per Gaussian, little endian, no header:
//   position float32 x 3 | scale float32 x 3 (linear) | colour uint8 x 4 (RGBA) |
//   rotation uint8 x 4 ((w, x, y, z) of the unit quaternion, q * 128 + 128, clamped to 0..255)
// RGB is 0.5 + C0 * SH degree 0, A the opacity, both scaled by 255, rounded and clamped.
// The format is lossy: only SH degree 0 survives, colours and rotations are quantised, and
// confidence and extra channels are dropped. Writing orders Gaussians as the reference
// converter does (largest scale_x * scale_y * scale_z * opacity first, ties by index).
#pragma once

#include "avsplat/core/gaussians.h"

#include <string>

namespace avsplat {

/// Reads a .splat file. Throws avsplat::IOError when the size is not a multiple of 32 bytes or
/// the file cannot be read.
GaussianCloud read_splat(const std::string& path);

/// Writes `cloud` (validated first) as a .splat file.
void write_splat(const std::string& path, const GaussianCloud& cloud);

}  // namespace avsplat
