// Reading and writing numpy .npy arrays and .npz archives (np.save, np.savez,
// np.savez_compressed), so that the predictions of a Python model reach the C++ tools without
// a conversion step.
//
// .npz: a zip archive with one "<name>.npy" entry per array, read and written with libzip.
// Entries may be stored or deflated; zip64 records and extra fields are handled, and every local
// header is checked against the central directory. Entries whose name does not end in ".npy"
// are skipped; encrypted, multi-disk or otherwise compressed entries are errors. Every entry's
// CRC-32 is verified, and an entry is never inflated beyond what its .npy header says it holds
// (a deflate bomb is an IOError, not gigabytes of memory).
//
// .npy: format versions 1.0, 2.0 and 3.0; dtypes bool ('|b1'), signed and unsigned integers of
// 1, 2, 4 and 8 bytes, float16, float32 and float64, in either byte order ('<', '>', '|', '=');
// C order, or Fortran order, which is transposed into C order on reading. Structured, string
// and object (pickled) arrays are errors.
//
// Errors: avsplat::IOError naming the file, and the entry where there is one, e.g.
// "preds.npz: entry 'points.npy': CRC-32 mismatch (corrupt data)".
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace avsplat {

/// Element types of .npy arrays avsplat reads and writes.
enum class NpyType { Bool, Int8, Int16, Int32, Int64, UInt8, UInt16, UInt32, UInt64, Float16, Float32, Float64 };

/// Bytes per element of `type`.
std::size_t npy_type_size(NpyType type);

/// numpy's name of `type` ("float32", "uint8", "bool", ...).
const char* npy_type_name(NpyType type);

/// One array: its name (the archive entry without ".npy"; the file name for read_npy), element
/// type, shape and elements in C (row-major) order and the host's byte order.
struct NpyArray {
    std::string name;
    NpyType type = NpyType::Float32;
    std::vector<std::size_t> shape;    ///< empty for a 0-d (scalar) array
    std::vector<unsigned char> bytes;  ///< size() * npy_type_size(type) bytes

    /// Number of elements: the product of the shape (1 for a 0-d array).
    std::size_t size() const;
    /// The shape as numpy prints it: "(2, 3)", "(5,)", "()".
    std::string shape_string() const;
    /// The elements converted to float32 (bool -> 0 / 1; integers and float64 rounded to the
    /// nearest float, so int64 beyond 2^24 and float64 beyond float range lose precision or
    /// become +-inf, as numpy's astype(np.float32)).
    std::vector<float> to_float32() const;
    /// The elements converted to float64 (exact except int64 / uint64 beyond 2^53).
    std::vector<double> to_float64() const;

    /// An array copied from `data` (shape given, C order). T is one of bool, the fixed-width
    /// integer types, float or double. Throws std::invalid_argument when data is null and the
    /// shape is not empty of elements.
    template <class T>
    static NpyArray from_data(std::string name, std::vector<std::size_t> shape, const T* data);
};

/// Parses one .npy file image of `size` bytes. `what` names it in error messages (a file, or
/// "file: entry 'x.npy'"); `name` becomes NpyArray::name. Throws avsplat::IOError.
NpyArray parse_npy(const unsigned char* data, std::size_t size, const std::string& what,
                   const std::string& name);

/// Reads a .npy file; the array's name is the file name without directory and ".npy".
NpyArray read_npy(const std::string& path);

/// All ".npy" entries of the .npz archive `path`, in archive order. Throws avsplat::IOError
/// when the file cannot be read, is not a valid archive, an entry is corrupt or unsupported, or
/// two entries have the same name.
std::vector<NpyArray> read_npz(const std::string& path);

/// Receives the name, type and shape (bytes empty) of every ".npy" entry, in archive order.
using NpzHeaderCheck = std::function<void(const std::vector<NpyArray>& headers)>;
/// As read_npz, but reads every entry's .npy header first (inflating nothing beyond it) and calls
/// `check` with them before any data is inflated, so that a caller refuses a wrong shape (by
/// throwing) before the archive's arrays take memory.
std::vector<NpyArray> read_npz(const std::string& path, const NpzHeaderCheck& check);

/// The array called `name` in `arrays`, or nullptr.
const NpyArray* find_array(const std::vector<NpyArray>& arrays, const std::string& name);

/// Whether write_npz deflates the entries (np.savez_compressed) or stores them (np.savez).
enum class NpzCompression { Stored, Deflated };

/// Writes `arrays` as an .npz archive that numpy.load reads: one "<name>.npy" entry each
/// (format 1.0, little endian, C order), with a fixed timestamp so that equal arrays give equal
/// files. Throws std::invalid_argument for an empty or duplicate name or an array whose
/// byte count does not match its shape, and avsplat::IOError when the file cannot be written.
/// zip64 records are written where sizes (4 GiB) or counts (65,535 entries) need them. The
/// archive is assembled in memory before it is written (atomically, see io/atomic_file.h).
void write_npz(const std::string& path, const std::vector<NpyArray>& arrays,
               NpzCompression compression = NpzCompression::Stored);

}  // namespace avsplat
