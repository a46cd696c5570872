#include "avsplat/io/splat.h"
#include "avsplat/io/atomic_file.h"

#include "avsplat/core/error.h"
#include "io/input_file.h"
#include "avsplat/core/sh.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>

namespace avsplat {

namespace {

constexpr std::size_t kRecord = 32;

std::uint8_t to_byte(double v) {
    return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
}

// The format is little endian; this library targets little-endian hosts (x86-64, aarch64).
static_assert(sizeof(float) == 4, "float32 expected");

}  // namespace

GaussianCloud read_splat(const std::string& path) {
    io::regular_file_size(path);
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in) throw IOError(path + ": cannot open for reading");
    const std::streamoff size = in.tellg();
    if (size < 0 || size % kRecord != 0)
        throw IOError(path + ": size " + std::to_string(size) +
                      " bytes is not a multiple of the 32-byte .splat record");
    const std::size_t n = static_cast<std::size_t>(size) / kRecord;
    std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
    in.seekg(0);
    if (!in.read(reinterpret_cast<char*>(bytes.data()), size))
        throw IOError(path + ": read failed");
    GaussianCloud c(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
        const unsigned char* r = &bytes[i * kRecord];
        std::memcpy(&c.means[3 * i], r, 12);
        std::memcpy(&c.scales[3 * i], r + 12, 12);
        for (int ch = 0; ch < 3; ++ch)
            c.sh[3 * i + ch] = static_cast<float>(sh::color_to_dc(r[24 + ch] / 255.0));
        c.opacities[i] = r[27] / 255.f;
        for (int k = 0; k < 4; ++k) c.rotations[4 * i + k] = (r[28 + k] - 128.f) / 128.f;
        if (c.rotations[4 * i] == 0.f && c.rotations[4 * i + 1] == 0.f &&
            c.rotations[4 * i + 2] == 0.f && c.rotations[4 * i + 3] == 0.f)
            throw IOError(path + ": record " + std::to_string(i) + " has a zero quaternion");
    }
    return c;
}

void write_splat(const std::string& path, const GaussianCloud& c) {
    validate(c);
    const int k = c.sh_coeffs();
    std::vector<double> key(c.size());
    for (std::size_t i = 0; i < c.size(); ++i)
        key[i] = double(c.scales[3 * i]) * c.scales[3 * i + 1] * c.scales[3 * i + 2] * c.opacities[i];
    std::vector<std::size_t> order(c.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key[a] > key[b]; });

    std::vector<unsigned char> bytes(c.size() * kRecord);
    for (std::size_t j = 0; j < c.size(); ++j) {
        const std::size_t i = order[j];
        unsigned char* r = &bytes[j * kRecord];
        std::memcpy(r, &c.means[3 * i], 12);
        std::memcpy(r + 12, &c.scales[3 * i], 12);
        for (int ch = 0; ch < 3; ++ch)
            r[24 + ch] = to_byte(255.0 * sh::dc_to_color<double>(c.sh[i * k * 3 + ch]));
        r[27] = to_byte(255.0 * c.opacities[i]);
        const float* q = &c.rotations[4 * i];
        const double norm = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] +
                                      double(q[2]) * q[2] + double(q[3]) * q[3]);
        for (int t = 0; t < 4; ++t) r[28 + t] = to_byte(q[t] / norm * 128.0 + 128.0);
    }
    AtomicFile out(path);
    out.write(bytes.data(), bytes.size());
    out.commit();
}

}  // namespace avsplat
