// Private: the SPZ container, bytes <-> header + attribute blocks (v2/v3 gzip, v4 ZSTD streams).
// The quantisation of the blocks is spz_attributes.h. Every size the file states is checked
// against the header and the file before anything is allocated, and decompression grows its
// output only as data actually arrives, up to the size the header implies.
#pragma once

#include "avsplat/io/spz.h"

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace avsplat::io::spz {

constexpr std::uint32_t kMagic = 0x5053474e;  // "NGSP", little endian
constexpr std::uint8_t kFlagAntialiased = 0x1;
constexpr std::uint8_t kFlagHasExtensions = 0x2;
constexpr std::size_t kLegacyHeaderSize = 16;  // v1..v3, inside the gzip stream
constexpr std::size_t kHeaderSize = 32;        // v4, plain
constexpr std::uint32_t kExtensionCoordinateSystem = 0xADBE0003u;  // Adobe's record: uint32 axes

/// SH coefficients per channel beyond the DC term for a file's SH degree 0..4: 0, 3, 8, 15, 24.
int sh_rest_for_degree(int degree);

/// The attribute blocks of an SPZ file, undecoded, in the file's order.
struct PackedSpz {
    int version = 4;
    std::uint32_t count = 0;
    int sh_degree = 0;  ///< as stored, 0..4
    int fractional_bits = 12;
    bool antialiased = false;
    /// Axes named by a v4 coordinate-system extension record (Niantic's value 1..8), if any.
    std::optional<SpzCoordinateSystem> coordinate_system;
    std::vector<std::uint8_t> positions;  ///< 9 bytes per Gaussian
    std::vector<std::uint8_t> alphas;     ///< 1
    std::vector<std::uint8_t> colors;     ///< 3
    std::vector<std::uint8_t> scales;     ///< 3
    std::vector<std::uint8_t> rotations;  ///< 3 (v2) or 4 (v3+)
    std::vector<std::uint8_t> sh;         ///< 3 * sh_rest_for_degree(sh_degree)
};

/// Parses a whole file. Throws IOError "<name>: <field>: <problem>".
PackedSpz unpack_container(const std::uint8_t* data, std::size_t size, const std::string& name);

/// The header only; v2/v3 inflate just its 16 bytes.
SpzHeader read_header(const std::uint8_t* data, std::size_t size, const std::string& name);

/// The file bytes of `packed` as `packed.version` (2, 3 or 4; v2 and v3 are written without
/// extensions).
std::vector<std::uint8_t> pack_container(const PackedSpz& packed);

}  // namespace avsplat::io::spz
