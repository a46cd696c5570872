// PlayCanvas's compressed PLY (".compressed.ply"), as written by SuperSplat, splat-transform and
// gsplat's ply_compressed exporter: a binary PLY whose Gaussians are packed into 16 bytes plus
// one byte per SH coefficient.
//
// Layout (element order as written; any order and extra elements are accepted when reading):
//   element chunk  ceil(N / 256) rows of float bounds for Gaussians 256 k .. 256 k + 255:
//                  min_x min_y min_z max_x max_y max_z (positions),
//                  min_scale_x .. max_scale_z (log scales, clamped to [-20, 20]),
//                  min_r min_g min_b max_r max_g max_b (colour 0.5 + C0 * f_dc; absent in the
//                  first version of the format, whose colours are then plain unorm values)
//   element vertex N rows of uint32:
//                  packed_position  11/10/11 bits of x/y/z between the chunk's bounds
//                  packed_rotation  smallest three: 2 bits of the index of the largest
//                                   component (w, x, y, z order), then 10 bits of each other
//                                   component c as c / sqrt(2) + 0.5 (the largest made >= 0)
//                  packed_scale     11/10/11 bits of log scale x/y/z between the chunk's bounds
//                  packed_color     8/8/8 bits of r/g/b between the chunk's bounds, 8 of opacity
//   element sh     N rows of uchar f_rest_0 .. f_rest_{3(K-1)-1} (channel-major, as 3DGS PLY):
//                  byte = clamp(trunc((f / 8 + 0.5) * 256), 0, 255); decoded as (u - 0.5) * 8
//                  with u = 0 for b = 0, 1 for b = 255, else (b + 0.5) / 256. Absent for degree 0.
// An n-bit field stores round(t * (2^n - 1)) of t in [0, 1] (0 when max - min < 1e-5), decoded as
// min + (max - min) * field / (2^n - 1). The encoding and decoding follow splat-transform 3.7.0
// and the PlayCanvas engine exactly; tests/python/test_compressed_ply.py holds us to
// splat-transform in both directions.
//
// What survives: means to 1/2047 (x, z) or 1/1023 (y) of the chunk's extent; log scales to
// 1/2047 or 1/1023 of the chunk's log-scale range; rotations to half of sqrt(2) / 1023 per component;
// colour to 1/255 of the chunk's colour range, opacity to 1/255; SH bands 1..3 to 1/32 (values
// outside [-4, 4] are clamped). Lost: confidence, extra channels, and the order of the Gaussians
// unless written with morton_order = false.
#pragma once

#include "avsplat/core/gaussians.h"
#include "avsplat/core/morton_order.h"

#include <cstddef>
#include <string>
#include <vector>

namespace avsplat {

/// Reads a compressed PLY file (binary little or big endian). SH degree from the sh element's
/// f_rest count (0, 9, 24 or 45); means, linear scales (exp of the decoded log scale),
/// rotations (w, x, y, z, unit), opacities in [0, 1] and SH (N, K, 3) as float32.
///
/// Throws IOError "<path>: <problem>" naming the element, property and row when the file is not
/// a compressed PLY (no chunk element, a missing packed_* or bounds property, a packed property
/// that is not uint32), is ASCII, has a chunk count other than ceil(N / 256), an sh element
/// whose count differs from the vertex count, chunk bounds that are not finite or decode outside
/// the float32 range (e.g. a log-scale bound above 87), or is truncated or longer
/// than its header says. No allocation is sized by a header count before the count is checked
/// against the bytes that are in the file.
GaussianCloud read_compressed_ply(const std::string& path);

/// The same from a file image of `size` bytes in memory; `name` stands for it in errors.
GaussianCloud parse_compressed_ply(const unsigned char* data, std::size_t size, const std::string& name);

/// Writes `cloud` (validated first: std::invalid_argument names the field and index) as a
/// binary little-endian compressed PLY with the chunk, vertex and (degree > 0) sh elements in
/// the property order that SuperSplat and the PlayCanvas engine expect. With `morton_order`
/// (the default, as splat-transform and SuperSplat write) the Gaussians are reordered along a
/// Morton curve of their means, so each chunk of 256 is compact and its bounds are tight; with
/// false they keep their order (coarser bounds for scattered input). Confidence and extra
/// channels are not written. Throws IOError naming the file when it cannot be written.
void write_compressed_ply(const std::string& path, const GaussianCloud& cloud, bool morton_order = true);

}  // namespace avsplat
