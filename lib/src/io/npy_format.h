// Private: the pieces of the .npy format (io/npy_format.cpp) that the .npz container (npz.cpp)
// uses besides the public parse_npy: the image write_npz stores, and the sizes a header implies,
// so that an entry is never inflated beyond what its own header says it holds.
#pragma once

#include "avsplat/io/npz.h"

#include <cstddef>
#include <string>
#include <vector>

namespace avsplat::io {

/// Bytes a .npy image needs before its header length is known (magic, version, length field).
constexpr std::size_t kNpyPrefixBytes = 12;
/// The largest header accepted. numpy writes headers under 64 KiB (a 64-dimensional shape takes
/// about 1.5 KiB); the limit keeps a forged header length from sizing an allocation.
constexpr std::size_t kNpyMaxHeader = std::size_t(1) << 20;

/// Where the data of the .npy image starting with data[0, size) begins (prefix + header
/// length), from its first min(size, kNpyPrefixBytes) bytes. Throws IOError (bad magic, an
/// unsupported version, a truncated prefix, a header over kNpyMaxHeader), `what` first.
std::size_t npy_data_offset(const unsigned char* data, std::size_t size, const std::string& what);

/// Bytes of array data the header in data[0, size) declares; `size` must reach
/// npy_data_offset(). Throws IOError as parse_npy does for the header and dtype.
std::size_t npy_data_size(const unsigned char* data, std::size_t size, const std::string& what);

/// The name, type and shape the header in data[0, size) declares (bytes left empty); `size` must
/// reach npy_data_offset(). Throws IOError as parse_npy does for the header and dtype.
NpyArray npy_header(const unsigned char* data, std::size_t size, const std::string& what, const std::string& name);

/// The .npy image (format 1.0, little endian, C order, header padded to 64 bytes as numpy
/// does) of `a`, whose bytes the caller has checked against its shape.
std::vector<unsigned char> npy_image(const NpyArray& a);

}  // namespace avsplat::io
