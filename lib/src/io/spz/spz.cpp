#include "avsplat/io/spz.h"

#include "avsplat/core/error.h"
#include "avsplat/io/atomic_file.h"
#include "io/input_file.h"
#include "io/spz/spz_attributes.h"
#include "io/spz/spz_container.h"

#include <zlib.h>

#include <cstring>
#include <fstream>
#include <stdexcept>
#include <vector>

namespace avsplat {

namespace {

std::vector<std::uint8_t> read_all(const std::string& path, std::size_t at_most = SIZE_MAX) {
    const std::uint64_t size = io::regular_file_size(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading");
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(size, at_most));
    std::vector<std::uint8_t> bytes(n);
    if (n && !in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(n)))
        throw IOError(path + ": read failed");
    return bytes;
}

}  // namespace

GaussianCloud parse_spz(const std::uint8_t* data, std::size_t size, const std::string& name,
                        const SpzReadOptions& options) {
    const io::spz::PackedSpz packed = io::spz::unpack_container(data, size, name);
    return io::spz::unpack_attributes(packed, packed.coordinate_system.value_or(options.coordinate_system));
}

GaussianCloud read_spz(const std::string& path, const SpzReadOptions& options) {
    const std::vector<std::uint8_t> bytes = read_all(path);
    return parse_spz(bytes.data(), bytes.size(), path, options);
}

SpzHeader read_spz_header(const std::string& path) {
    // 64 KiB of a gzip stream always inflate to more than the 16 header bytes.
    const std::vector<std::uint8_t> bytes = read_all(path, 1 << 16);
    return io::spz::read_header(bytes.data(), bytes.size(), path);
}

bool is_spz(const std::uint8_t* data, std::size_t size) {
    if (size >= 4 && std::memcmp(data, "NGSP", 4) == 0) return true;
    if (size < 2 || data[0] != 0x1f || data[1] != 0x8b) return false;
    z_stream z{};
    if (inflateInit2(&z, 16 + MAX_WBITS) != Z_OK) return false;
    std::uint8_t head[4] = {};
    z.next_in = const_cast<Bytef*>(data);
    z.avail_in = static_cast<uInt>(std::min<std::size_t>(size, 1 << 20));
    z.next_out = head;
    z.avail_out = sizeof head;
    int rc = Z_OK;
    while (z.avail_out > 0 && (rc == Z_OK) && z.avail_in > 0) rc = inflate(&z, Z_NO_FLUSH);
    const bool ok = z.avail_out == 0 && std::memcmp(head, "NGSP", 4) == 0;
    inflateEnd(&z);
    return ok;
}

bool is_spz_file(const std::string& path) {
    try {
        const std::vector<std::uint8_t> bytes = read_all(path, 1 << 16);
        return is_spz(bytes.data(), bytes.size());
    } catch (const IOError&) {
        return false;
    }
}

void write_spz(const std::string& path, const GaussianCloud& cloud, const SpzWriteOptions& options) {
    validate(cloud);
    if (options.version < 2 || options.version > 4)
        throw std::invalid_argument("SpzWriteOptions.version: " + std::to_string(options.version) +
                                    " cannot be written (2, 3 and 4 can)");
    if (options.fractional_bits < -1 || options.fractional_bits > 23)
        throw std::invalid_argument("SpzWriteOptions.fractional_bits: " + std::to_string(options.fractional_bits) +
                                    " is outside -1..23");
    if (cloud.size() > 0xffffffffu)
        throw std::invalid_argument("GaussianCloud: " + std::to_string(cloud.size()) +
                                    " Gaussians exceed SPZ's 32-bit count");
    const std::vector<std::uint8_t> bytes = io::spz::pack_container(io::spz::pack_attributes(cloud, options));
    AtomicFile out(path);
    out.write(bytes.data(), bytes.size());
    out.commit();
}

}  // namespace avsplat
