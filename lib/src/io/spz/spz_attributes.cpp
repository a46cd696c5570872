#include "io/spz/spz_attributes.h"

#include "avsplat/core/interrupt.h"
#include "avsplat/core/sh.h"
#include "core/interrupt_poll.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace avsplat::io::spz {

namespace {

constexpr double kSqrt1_2 = 0.70710678118654752440;
constexpr std::uint32_t kRotationMask = (1u << 9) - 1;  // 9-bit magnitudes of the smallest three

std::uint8_t to_byte(double v) {
    // NaN cannot reach here (the cloud is validated); +-inf clamps.
    return static_cast<std::uint8_t>(std::clamp(std::round(v), 0.0, 255.0));
}

// SH coefficient c as the reference quantises it: round(128 c) + 128, then to the centre of a
// bucket of 2^(8 - bits) values (so that 0 stays exact), clamped to a byte.
std::uint8_t quantize_sh(double c, int bits) {
    const int bucket = 1 << (8 - bits);
    const double q = std::clamp(std::round(c * 128.0) + 128.0, -1024.0, 1024.0);
    int v = static_cast<int>(q);
    // C++ division truncates toward zero, as the reference's does: keep its buckets.
    v = (v + bucket / 2) / bucket * bucket;
    return static_cast<std::uint8_t>(std::clamp(v, 0, 255));
}

}  // namespace

AxisFlip axis_flip(SpzCoordinateSystem axes) {
    const int bits = static_cast<int>(axes);  // Niantic's value - 1: bit 0 Right, bit 1 Up, bit 2 Front
    const float x = (bits & 1) ? 1.f : -1.f;
    const float y = (bits & 2) ? -1.f : 1.f;
    const float z = (bits & 4) ? 1.f : -1.f;
    AxisFlip f;
    f.position = {x, y, z};
    f.quaternion_xyz = {y * z, x * z, x * y};
    // Parity of each real SH basis function (avsplat/core/sh.h's order) in x, y and z:
    //   band 1: y, z, x
    //   band 2: xy, yz, 2z^2-x^2-y^2, xz, x^2-y^2
    //   band 3: y(3x^2-y^2), xyz, y(4z^2-x^2-y^2), z(2z^2-3x^2-3y^2), x(4z^2-x^2-y^2), z(x^2-y^2), x(x^2-3y^2)
    f.sh = {y, z, x,
            x * y, y * z, 1.f, x * z, 1.f,
            y, x * y * z, y, z, x, z, x};
    return f;
}

PackedSpz pack_attributes(const GaussianCloud& c, const SpzWriteOptions& o) {
    const std::size_t n = c.size();
    const AxisFlip flip = axis_flip(o.coordinate_system);
    PackedSpz p;
    p.version = o.version;
    p.count = static_cast<std::uint32_t>(n);
    p.sh_degree = c.sh_degree;
    p.antialiased = c.antialiased;
    // Millions of Gaussians take seconds here: poll every 256 (serial loops on the caller's thread).
    InterruptPoll poll;
    const auto poll_at = [&poll](std::size_t i) {
        if (poll.stop(std::int64_t(i))) throw Interrupted();
    };

    // Fractional bits: 12 as the reference, fewer when the scene is larger than 24 bits hold.
    constexpr double kMaxFixed = (1 << 23) - 1;
    double largest = 0;
    std::size_t largest_at = 0;
    for (std::size_t i = 0; i < c.means.size(); ++i)
        if (std::fabs(double(c.means[i])) > largest) largest = std::fabs(double(c.means[i])), largest_at = i;
    int bits = o.fractional_bits;
    if (bits < 0) {
        bits = 12;
        while (bits > 0 && std::round(std::ldexp(largest, bits)) > kMaxFixed) --bits;
    }
    if (std::round(std::ldexp(largest, bits)) > kMaxFixed)
        throw std::invalid_argument("GaussianCloud.means[" + std::to_string(largest_at / 3) + "]: coordinate " +
                                    std::to_string(c.means[largest_at]) + " does not fit SPZ's 24-bit positions with " +
                                    std::to_string(bits) + " fractional bits");
    p.fractional_bits = bits;

    p.positions.resize(9 * n);
    for (std::size_t i = 0; i < 3 * n; ++i) {
        poll_at(i);
        const auto v = static_cast<std::int32_t>(std::round(std::ldexp(double(flip.position[i % 3]) * c.means[i], bits)));
        for (int b = 0; b < 3; ++b) p.positions[3 * i + b] = static_cast<std::uint8_t>((v >> (8 * b)) & 0xff);
    }
    p.alphas.resize(n);
    for (std::size_t i = 0; i < n; ++i) p.alphas[i] = to_byte(255.0 * c.opacities[i]);
    const int k = c.sh_coeffs();
    p.colors.resize(3 * n);
    for (std::size_t i = 0; i < n; ++i)
        for (int ch = 0; ch < 3; ++ch)
            p.colors[3 * i + ch] = to_byte(255.0 * (kColorScale * c.sh[(i * k) * 3 + ch] + 0.5));
    p.scales.resize(3 * n);
    for (std::size_t i = 0; i < 3 * n; ++i) {
        poll_at(i);
        p.scales[i] = to_byte(16.0 * (std::log(double(c.scales[i])) + 10.0));
    }

    const int rbytes = o.version >= 3 ? 4 : 3;
    p.rotations.resize(rbytes * n);
    for (std::size_t i = 0; i < n; ++i) {
        poll_at(i);
        const float* r = &c.rotations[4 * i];
        const double norm = std::sqrt(double(r[0]) * r[0] + double(r[1]) * r[1] + double(r[2]) * r[2] + double(r[3]) * r[3]);
        // The file's order is x, y, z, w.
        double q[4] = {flip.quaternion_xyz[0] * r[1] / norm, flip.quaternion_xyz[1] * r[2] / norm,
                       flip.quaternion_xyz[2] * r[3] / norm, r[0] / norm};
        std::uint8_t* out = &p.rotations[rbytes * i];
        if (rbytes == 3) {
            const double s = q[3] < 0 ? -1.0 : 1.0;  // w >= 0, derived on reading
            for (int t = 0; t < 3; ++t) out[t] = to_byte(127.5 * (s * q[t] + 1.0));
            continue;
        }
        int largest_k = 0;
        for (int t = 1; t < 4; ++t)
            if (std::fabs(q[t]) > std::fabs(q[largest_k])) largest_k = t;
        const bool negate = q[largest_k] < 0;  // q and -q are one rotation: make the largest positive
        std::uint32_t word = static_cast<std::uint32_t>(largest_k);
        for (int t = 0; t < 4; ++t) {
            if (t == largest_k) continue;
            const std::uint32_t sign = (q[t] < 0) != negate ? 1u : 0u;
            const auto mag = static_cast<std::uint32_t>(
                std::min<double>(kRotationMask, std::floor(kRotationMask * std::fabs(q[t]) / kSqrt1_2 + 0.5)));
            word = (word << 10) | (sign << 9) | mag;
        }
        for (int b = 0; b < 4; ++b) out[b] = static_cast<std::uint8_t>(word >> (8 * b));
    }

    const int rest = k - 1;  // coefficients per channel beyond DC
    p.sh.resize(3 * std::size_t(rest) * n);
    for (std::size_t i = 0; i < n; ++i) {
        poll_at(i);
        for (int j = 0; j < rest; ++j)
            for (int ch = 0; ch < 3; ++ch)
                p.sh[(i * rest + j) * 3 + ch] =
                    quantize_sh(double(flip.sh[j]) * c.sh[(i * k + 1 + j) * 3 + ch], j < 3 ? 5 : 4);
    }
    return p;
}

GaussianCloud unpack_attributes(const PackedSpz& p, SpzCoordinateSystem axes) {
    const std::size_t n = p.count;
    const int degree = std::min(p.sh_degree, 3);  // a file's band 4 is dropped
    const int file_rest = sh_rest_for_degree(p.sh_degree);
    const AxisFlip flip = axis_flip(axes);
    GaussianCloud c(n, degree);
    c.antialiased = p.antialiased;
    const int k = c.sh_coeffs();

    for (std::size_t i = 0; i < 3 * n; ++i) {
        const std::uint8_t* b = &p.positions[3 * i];
        std::int32_t v = std::int32_t(b[0]) | std::int32_t(b[1]) << 8 | std::int32_t(b[2]) << 16;
        if (v & 0x800000) v -= 1 << 24;  // sign extension
        c.means[i] = static_cast<float>(flip.position[i % 3] * std::ldexp(double(v), -p.fractional_bits));
    }
    for (std::size_t i = 0; i < n; ++i) c.opacities[i] = static_cast<float>(p.alphas[i] / 255.0);
    for (std::size_t i = 0; i < n; ++i)
        for (int ch = 0; ch < 3; ++ch)
            c.sh[(i * k) * 3 + ch] = static_cast<float>((p.colors[3 * i + ch] / 255.0 - 0.5) / kColorScale);
    for (std::size_t i = 0; i < 3 * n; ++i) c.scales[i] = static_cast<float>(std::exp(p.scales[i] / 16.0 - 10.0));

    for (std::size_t i = 0; i < n; ++i) {
        double q[4];  // x, y, z, w
        if (p.version == 2) {
            const std::uint8_t* b = &p.rotations[3 * i];
            double s = 0;
            for (int t = 0; t < 3; ++t) q[t] = b[t] / 127.5 - 1.0, s += q[t] * q[t];
            q[3] = std::sqrt(std::max(0.0, 1.0 - s));
        } else {
            const std::uint8_t* b = &p.rotations[4 * i];
            std::uint32_t word = std::uint32_t(b[0]) | std::uint32_t(b[1]) << 8 | std::uint32_t(b[2]) << 16 |
                                 std::uint32_t(b[3]) << 24;
            const int largest_k = static_cast<int>(word >> 30);
            double s = 0;
            for (int t = 3; t >= 0; --t) {
                if (t == largest_k) continue;
                const double v = kSqrt1_2 * double(word & kRotationMask) / kRotationMask;
                q[t] = (word >> 9) & 1u ? -v : v;
                s += v * v;
                word >>= 10;
            }
            q[largest_k] = std::sqrt(std::max(0.0, 1.0 - s));
        }
        // Any byte pattern gives a non-zero quaternion (v2: |xyz| > 0 always; v3: the largest is
        // 1 when the others are 0), so normalising is safe; hostile bytes may exceed unit norm.
        const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        float* r = &c.rotations[4 * i];
        r[0] = static_cast<float>(q[3] / norm);
        for (int t = 0; t < 3; ++t) r[1 + t] = static_cast<float>(flip.quaternion_xyz[t] * q[t] / norm);
    }

    for (std::size_t i = 0; i < n; ++i)
        for (int j = 0; j + 1 < k; ++j)
            for (int ch = 0; ch < 3; ++ch)
                c.sh[(i * k + 1 + j) * 3 + ch] =
                    static_cast<float>(flip.sh[j] * (p.sh[(i * file_rest + j) * 3 + ch] - 128.0) / 128.0);
    return c;
}

}  // namespace avsplat::io::spz
