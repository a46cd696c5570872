// The .ksplat format of mkkellogg's GaussianSplats3D (read only: no viewer needs it written, and
// every reader of it also reads formats avsplat writes).
//
// Layout (little endian), from GaussianSplats3D's SplatBuffer, version 0.1:
//   main header, 4096 bytes: uint8 major (0), minor (>= 1); uint32 at byte 4 the section count
//     (max), at 8 the sections in use, at 12 the Gaussian capacity, at 16 the Gaussian count;
//     uint16 at 20 the compression level (0, 1 or 2); float32 at 24 the scene centre (3), at 36
//     and 40 the SH range of level 2 (0 means -1.5 and 1.5).
//   one 1024-byte header per section: uint32 at 0 its Gaussian count, at 4 its capacity, at 8
//     the bucket capacity, at 12 the bucket count; float32 at 16 the bucket block size; uint16 at
//     20 the bytes per bucket (12: a float32 centre); uint32 at 24 the position quantisation
//     range (0 means 32767), at 32 the full and at 36 the partially filled bucket count; uint16 at
//     40 the section's SH degree (0..2).
//   per section, in order: the partially filled buckets' lengths (uint32 each), the bucket
//     centres, then `capacity` records of
//       level 0: position float32 x 3, scale float32 x 3 (linear), rotation float32 w, x, y, z,
//                RGBA uint8 x 4, SH float32
//       level 1, 2: position uint16 x 3 as (q - range) * block / 2 / range + the bucket's centre,
//                scale and rotation float16, RGBA uint8 x 4, SH float16 (1) or uint8 over the
//                header's SH range (2)
//     where SH is bands 1..2, channel-major within a band (9 values for degree 1, 24 for 2).
//   Gaussians of one section fill its full buckets (bucket capacity each) first, then the
//   partially filled ones in order.
// RGB is 0.5 + C0 * DC and A the opacity, 8 bits each. What survives: SH degree 0..2 (a file's
// sections of lower degree are zero-padded to the highest), positions to the quantisation step,
// scales and rotations to float16 (levels 1 and 2), colour and opacity to 8 bits. Axes are taken
// as stored (GaussianSplats3D writes the coordinates of its PLY input unchanged).
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <cstdint>
#include <string>

namespace avsplat {

/// Reads a .ksplat file. Throws avsplat::IOError naming the file and the field
/// ("sections[1].bucketCount", "sections[0].gaussians[17]: bucket ...") for a malformed,
/// truncated or unsupported file (version other than 0.1+, compression level above 2, SH degree
/// above 2); every section is checked against the file size before anything is allocated.
GaussianCloud read_ksplat(const std::string& path);

/// As read_ksplat, from `size` bytes in memory; `name` stands for the file in error messages.
GaussianCloud parse_ksplat(const std::uint8_t* data, std::size_t size, const std::string& name);

/// Whether the regular file at `path` looks like .ksplat: the format has no magic number, so this
/// is a plausibility check of its header (version 0.1 or later, compression level 0..2, a section
/// count whose headers fit the file, a Gaussian count no larger than the file could hold, and
/// header bytes 2, 3 and 44..4095 zero as GaussianSplats3D writes them). Never throws.
bool is_ksplat_file(const std::string& path);

}  // namespace avsplat
