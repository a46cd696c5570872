// The generic PLY layer: any element, any property (scalar or list), any encoding (ASCII, binary
// little or big endian), read into named columns, and written back from them. The 3DGS reader
// (io/ply.h), the PlayCanvas compressed PLY format and the simulator's mesh all sit on it.
//
// Values are held as double, which represents every PLY type exactly (int8..uint32, float32,
// float64); a column remembers its declared type so that writing gives the same file layout.
// Every problem with a file throws avsplat::IOError naming the file (or the `name` given for a
// buffer) and what is wrong; no allocation is sized by a header count before the count is
// checked against the bytes that are there.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace avsplat {

enum class PlyType : std::uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };
enum class PlyFormat : std::uint8_t { Ascii, BinaryLittleEndian, BinaryBigEndian };

/// One property of an element, as a column of `count` rows.
struct PlyColumn {
    std::string name;
    PlyType type = PlyType::Float32;   ///< the value type (of the items, for a list)
    bool is_list = false;
    PlyType count_type = PlyType::UInt8;  ///< lists only: the type of the per-row item count
    /// Scalars: one value per row. Lists: the items of every row, concatenated.
    std::vector<double> values;
    /// Lists only: row i's items are values[offsets[i] .. offsets[i + 1]); count + 1 entries.
    std::vector<std::uint64_t> offsets;
};

struct PlyElement {
    std::string name;
    std::uint64_t count = 0;
    std::vector<PlyColumn> columns;
    /// The column called `name`, or nullptr.
    const PlyColumn* find(const std::string& column) const;
};

struct PlyData {
    PlyFormat format = PlyFormat::BinaryLittleEndian;
    std::vector<std::string> comments;  ///< "comment" lines, without the keyword
    std::vector<PlyElement> elements;   ///< in file order
    /// The element called `name`, or nullptr.
    const PlyElement* find(const std::string& element) const;
};

/// Reads every element of a PLY file.
PlyData read_ply_data(const std::string& path);

/// Parses a PLY file image of `size` bytes held in memory; `name` stands for it in errors.
PlyData parse_ply_data(const unsigned char* data, std::size_t size, const std::string& name);

/// Writes `data` as binary little endian (whatever data.format says), values converted to each
/// column's type. Throws std::invalid_argument when a column's length does not match its
/// element's count, a name is not a single token, or a value does not fit its integer type;
/// IOError when the file cannot be written (the previous file is then left as it was).
void write_ply_data(const std::string& path, const PlyData& data);

}  // namespace avsplat
