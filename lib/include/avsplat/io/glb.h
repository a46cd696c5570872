// Binary glTF (.glb) with the Khronos KHR_gaussian_splatting extension, as PlayCanvas's
// splat-transform 3.7 writes it: one POINTS primitive whose attributes are
//   POSITION                                  VEC3 float (with min/max)
//   COLOR_0                                   VEC4 uint8 normalized: 0.5 + C0 * DC and opacity
//                                             (a fallback for viewers without the extension)
//   KHR_gaussian_splatting:ROTATION           VEC4 float, quaternion x, y, z, w
//   KHR_gaussian_splatting:SCALE              VEC3 float, linear scales (see below)
//   KHR_gaussian_splatting:OPACITY            SCALAR float in [0, 1]
//   KHR_gaussian_splatting:SH_DEGREE_l_COEF_n VEC3 float (r, g, b), l = 0..3, n = 0..2l
// each in its own buffer view of the GLB's binary chunk. The SH basis is 3DGS PLY's (real SH with
// the Condon-Shortley phase). Axes: glTF's (+Y up, +Z forward, +X left); avsplat's are OpenCV's
// (x right, y down, z forward), so reading and writing turn the scene 180 degrees about z (x and
// y negate, quaternions and SH coefficients follow), as splat-transform 3.7 turns PLY input.
//
// Scales: splat-transform 3.7 writes linear scales, while the extension's review draft says
// SCALE is stored as log(scale). Both directions follow splat-transform by default;
// GlbOptions::log_scales selects the draft's reading.
//
// What survives: everything of the 3DGS model at float32 (SH degree 0..3) and the Gaussians'
// order. What is lost: `antialiased`, confidence and extra channels.
//
// Reading also accepts what the extension allows beyond splat-transform's writer: the
// normalized integer rotations, scales and opacities of its attribute table, interleaved buffer
// views, several Gaussian primitives (concatenated in mesh and primitive order, SH
// zero-padded to the highest degree), and a missing
// SH_DEGREE_0_COEF_0 when COLOR_0 is present (the DC colour is then taken from COLOR_0). It
// refuses what would silently change the scene: sparse accessors, buffers outside the GLB,
// node transforms, and SH degrees given in part.
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <cstdint>
#include <string>

namespace avsplat {

struct GlbOptions {
    /// false (default): SCALE holds linear scales, as splat-transform 3.7 writes and reads;
    /// true: SCALE holds log(scale), as the extension's review draft specifies.
    bool log_scales = false;
};

/// Reads the Gaussian primitives of a .glb file into one cloud. Throws avsplat::IOError naming
/// the file and the field ("accessors[3].count", "KHR_gaussian_splatting:SCALE[12]", ...) for a
/// malformed, truncated or unsupported file; every accessor is checked against its buffer view
/// and the binary chunk before anything is allocated, so allocation is bounded by the file size.
GaussianCloud read_glb(const std::string& path, const GlbOptions& options = {});

/// As read_glb, from `size` bytes in memory; `name` stands for the file in error messages.
GaussianCloud parse_glb(const std::uint8_t* data, std::size_t size, const std::string& name,
                        const GlbOptions& options = {});

/// True when `data` starts with the GLB magic "glTF". Never throws.
bool is_glb(const std::uint8_t* data, std::size_t size);

/// Writes `cloud` (validated first) as a .glb file with KHR_gaussian_splatting, atomically, in
/// the layout above. Throws std::invalid_argument for an invalid cloud or one larger than a GLB
/// holds (4 GiB), avsplat::IOError when the file cannot be written. Cost: O(N) time, one copy of
/// the attributes in memory.
void write_glb(const std::string& path, const GaussianCloud& cloud, const GlbOptions& options = {});

}  // namespace avsplat
