// Niantic's SPZ ("splat zip"), the compressed format of Scaniverse and Niantic's spz library.
//
// Versions read: 2, 3 and 4. Versions written: 4 (default), 3 and 2 (for readers that predate 4 or 3).
//   v2, v3  one gzip stream: a 16-byte header (magic "NGSP", version, count, SH degree,
//           fractional bits, flags, reserved) then the attribute blocks in the order below.
//   v4      a 32-byte plain header (the same fields, then the stream count and the byte offset of
//           the table of contents), optional extension records, the table of contents (per
//           stream: compressed and uncompressed size, uint64 each) and one ZSTD stream per
//           attribute.
// Attributes, per Gaussian, in this order:
//   position  3 x 24-bit signed fixed point with the header's fractional bits (written: 12, fewer
//             when the scene is larger than +-2048 units; 1/4096 unit resolution at 12)
//   alpha     uint8, round(255 * opacity)
//   colour    uint8 x 3, round(255 * (0.15 * dc + 0.5)) (the reference's colour scale 0.15, not C0,
//             so that DC colours somewhat outside [0, 1] survive)
//   scale     uint8 x 3, round(16 * (log(scale) + 10)): log scales in [-10, 5.94] at 1/16 steps
//   rotation  v2: x, y, z of the unit quaternion with w >= 0 as round(127.5 * (q + 1));
//             v3+: smallest three (2-bit index of the largest component, three 10-bit signed
//             values of 9-bit magnitude in [-1/sqrt2, 1/sqrt2])
//   SH        bands 1..3 (4 in the newest files), coefficient-major, channel inner, uint8
//             round(128 * c) + 128 rounded to 5 bits in band 1 and 4 bits above.
// What survives: SH degree 0..3 (a file's band 4 is dropped on read), `antialiased`. What is
// lost: confidence and extra channels, and the precision above. Opacities are written as the
// file's alpha byte, which 0 and 1 map onto exactly.
//
// Axes: the SPZ specification stores RUB (x right, y up, z back: OpenGL, three.js). avsplat's
// world is OpenCV's RDF (x right, y down, z forward), so reading turns the file's axes into ours
// and writing turns ours into the file's: for RUB a 180-degree rotation about x (y and z negate,
// the quaternion's y and z negate, SH coefficients change sign by the parity of their basis
// function). Files written by PlayCanvas's splat-transform 3.7 store PLY's axes (RDF) without
// conversion, contrary to the specification: read them with coordinate_system RDF.
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <cstdint>
#include <string>

namespace avsplat {

/// The axes an SPZ file's data is stored in (Niantic's CoordinateSystem names: Left/Right,
/// Down/Up, Back/Front). RUB is the specification's; RDF is avsplat's and PLY's.
enum class SpzCoordinateSystem { LDB, RDB, LUB, RUB, LDF, RDF, LUF, RUF };

struct SpzReadOptions {
    /// The axes the file's data is stored in, converted to avsplat's (RDF) on reading. A file whose
    /// coordinate-system extension record (Adobe's 0xADBE0003, values 1..8) names its axes
    /// overrides this; a record naming a 90-degree rotated family (9..16) is an IOError.
    SpzCoordinateSystem coordinate_system = SpzCoordinateSystem::RUB;
};

struct SpzWriteOptions {
    /// 4 (ZSTD streams, the default), 3 (one gzip stream, for readers that predate 4) or 2 (one
    /// gzip stream whose rotations are x, y, z at 8 bits, for readers that predate 3).
    int version = 4;
    /// The axes to store the data in. Leave RUB unless the reader is known to expect another.
    SpzCoordinateSystem coordinate_system = SpzCoordinateSystem::RUB;
    /// Fractional bits of the fixed-point positions, 0..23; -1 (default): 12 as the reference
    /// writes, or fewer when the largest |coordinate| needs them to fit 24 bits.
    int fractional_bits = -1;
};

/// The header fields of an SPZ file (read_spz_header reads only these).
struct SpzHeader {
    int version = 0;
    std::uint32_t count = 0;        ///< Gaussians
    int sh_degree = 0;              ///< as stored (0..4)
    int fractional_bits = 0;
    bool antialiased = false;
};

/// Reads an SPZ file (v2, v3 or v4) into a cloud in avsplat's axes: means (N, 3), linear scales,
/// unit rotations (w, x, y, z), opacities in [0, 1], SH of the file's degree (at most 3), and
/// `antialiased` from the header's flag. Throws avsplat::IOError naming the file and the field
/// for a malformed, truncated or lying file; sizes are checked before anything is allocated and
/// decompression stops at the size the header implies.
GaussianCloud read_spz(const std::string& path, const SpzReadOptions& options = {});

/// As read_spz, from `size` bytes in memory; `name` stands for the file in error messages.
GaussianCloud parse_spz(const std::uint8_t* data, std::size_t size, const std::string& name,
                        const SpzReadOptions& options = {});

/// The header of an SPZ file (a v2/v3 file's gzip stream is inflated only as far as the header).
/// Throws avsplat::IOError as read_spz does for a header it cannot read.
SpzHeader read_spz_header(const std::string& path);

/// True when `data` (a file's first `size` bytes; a few hundred suffice) starts an SPZ file: the v4
/// magic "NGSP", or a gzip stream whose first 4 inflated bytes are "NGSP". Never throws.
bool is_spz(const std::uint8_t* data, std::size_t size);

/// is_spz on the first 64 KiB of the regular file at `path`; false when it cannot be read.
bool is_spz_file(const std::string& path);

/// Writes `cloud` (validated first) as SPZ, atomically. `cloud.antialiased` sets the header's
/// antialiased flag. Throws std::invalid_argument for an invalid cloud, a version other than 2,
/// 3 or 4, fractional bits outside -1..23, or a coordinate that does not fit 24 bits (naming its
/// index); avsplat::IOError when the file cannot be written.
void write_spz(const std::string& path, const GaussianCloud& cloud, const SpzWriteOptions& options = {});

}  // namespace avsplat
