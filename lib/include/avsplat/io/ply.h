// 3DGS PLY reading and writing (the INRIA layout every splat viewer reads).
//
// Vertex properties: x y z nx ny nz f_dc_0..2 f_rest_0..(3*(K-1)-1) opacity scale_0..2 rot_0..3.
// On disk opacity is a logit, scale is log(scale), rot is (w, x, y, z) and f_rest is
// channel-major (all R coefficients of bands 1.., then G, then B); in memory GaussianCloud holds
// opacity in [0, 1], linear scales and SH as N x K x 3 (DESIGN.md).
//
// Reading accepts binary little endian, binary big endian and ASCII; properties in any order;
// float, double and the integer PLY types; SH degree 0..3 inferred from the number of f_rest
// properties; any other vertex property (e.g. "confidence") is kept: "confidence" becomes
// GaussianCloud::confidence, everything else a named extra channel; normals are dropped.
// Writing produces binary little endian with SH of the degree stored (nothing for absent bands),
// then "confidence" and the extra channels as float properties.
//
// Every problem with a file throws avsplat::IOError naming the file and what is wrong (bad
// header, missing property, truncated data, counts that cannot fit the file). No allocation is
// sized by a header value before it is checked against the file size.
#pragma once

#include "avsplat/gaussians.h"

#include <string>

namespace avsplat {

/// Reads a 3DGS PLY file.
GaussianCloud read_ply(const std::string& path);

/// Writes `cloud` as a binary little-endian 3DGS PLY file. Validates shapes first
/// (std::invalid_argument); values are written as they are (opacity 0 or 1 give +-Inf logits,
/// which every 3DGS reader maps back).
void write_ply(const std::string& path, const GaussianCloud& cloud);

}  // namespace avsplat
