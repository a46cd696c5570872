// Reading GaussianSplats3D's .ksplat (avsplat/io/ksplat.h).
#include "avsplat/io/ksplat.h"

#include "avsplat/core/error.h"
#include "avsplat/core/sh.h"
#include "io/input_file.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <vector>

namespace avsplat {

namespace {

constexpr std::size_t kHeaderSize = 4096;
constexpr std::size_t kSectionHeaderSize = 1024;
constexpr std::uint32_t kDefaultQuantRange = 32767;  // levels 1 and 2
constexpr float kDefaultShMin = -1.5f, kDefaultShMax = 1.5f;
constexpr int kShValues[3] = {0, 9, 24};  // per degree: bands 1..d, 3 channels

[[noreturn]] void fail(const std::string& name, const std::string& what) { throw IOError(name + ": " + what); }

std::uint16_t le16(const std::uint8_t* p) {
    std::uint16_t v;
    std::memcpy(&v, p, 2);
    return v;
}
std::uint32_t le32(const std::uint8_t* p) {
    std::uint32_t v;
    std::memcpy(&v, p, 4);
    return v;
}
float lef32(const std::uint8_t* p) {
    float v;
    std::memcpy(&v, p, 4);
    return v;
}

// IEEE 754 binary16 to float, subnormals, infinities and NaN included.
float half_to_float(std::uint16_t h) {
    const int sign = h >> 15, exponent = (h >> 10) & 0x1f, mantissa = h & 0x3ff;
    float v;
    if (exponent == 0) v = std::ldexp(float(mantissa), -24);
    else if (exponent == 31) v = mantissa ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
    else v = std::ldexp(float(mantissa | 0x400), exponent - 25);
    return sign ? -v : v;
}

struct Header {
    int major = 0, minor = 0;
    std::uint32_t max_sections = 0, count = 0;
    int level = 0;
    float sh_min = kDefaultShMin, sh_max = kDefaultShMax;
};

int bytes_per_gaussian(int level, int sh_degree) {
    const int base = level == 0 ? 44 : 24;
    const int per_sh = level == 0 ? 4 : level == 1 ? 2 : 1;
    return base + kShValues[sh_degree] * per_sh;
}

// The header fields (from the first 4096 bytes of a file of `size` bytes), or an error message
// (empty when valid).
std::string parse_header(const std::uint8_t* d, std::uint64_t size, Header& h) {
    if (size < kHeaderSize) return "header: the file is shorter than the 4096-byte header";
    h.major = d[0];
    h.minor = d[1];
    if (h.major != 0 || h.minor < 1)
        return "version: " + std::to_string(h.major) + "." + std::to_string(h.minor) + " is not supported (0.1 and later are)";
    h.max_sections = le32(d + 4);
    h.count = le32(d + 16);
    h.level = le16(d + 20);
    if (h.level > 2) return "compressionLevel: " + std::to_string(h.level) + " is not 0, 1 or 2";
    if (const float lo = lef32(d + 36); lo != 0) h.sh_min = lo;
    if (const float hi = lef32(d + 40); hi != 0) h.sh_max = hi;
    if (!std::isfinite(h.sh_min) || !std::isfinite(h.sh_max))
        return "minSphericalHarmonicsCoeff: the SH range is not finite";
    if (h.max_sections == 0) return "maxSectionCount: 0 sections";
    if (h.max_sections > (size - kHeaderSize) / kSectionHeaderSize)
        return "maxSectionCount: " + std::to_string(h.max_sections) + " section headers do not fit the file of " +
               std::to_string(size) + " bytes";
    return "";
}

}  // namespace

GaussianCloud parse_ksplat(const std::uint8_t* data, std::size_t size, const std::string& name) {
    Header h;
    if (const std::string why = parse_header(data, size, h); !why.empty()) fail(name, why);

    // First pass: every section's layout checked against the file, the SH degree, the total.
    struct Section {
        std::uint32_t count, capacity, bucket_capacity, buckets, bucket_bytes, quant_range, full, partial;
        float block;
        int sh_degree;
        std::size_t base;  // file offset of the partial bucket lengths
        std::size_t data;  // file offset of the records
        int stride;
    };
    std::vector<Section> sections;
    std::size_t at = kHeaderSize + std::size_t(h.max_sections) * kSectionHeaderSize;
    std::uint64_t total = 0;
    int degree = 0;
    for (std::uint32_t s = 0; s < h.max_sections; ++s) {
        const std::uint8_t* sh = data + kHeaderSize + std::size_t(s) * kSectionHeaderSize;
        const std::string where = "sections[" + std::to_string(s) + "].";
        Section sec{};
        sec.count = le32(sh);
        sec.capacity = le32(sh + 4);
        sec.bucket_capacity = le32(sh + 8);
        sec.buckets = le32(sh + 12);
        sec.block = lef32(sh + 16);
        sec.bucket_bytes = le16(sh + 20);
        sec.quant_range = le32(sh + 24);
        if (sec.quant_range == 0) sec.quant_range = h.level == 0 ? 1 : kDefaultQuantRange;
        sec.full = le32(sh + 32);
        sec.partial = le32(sh + 36);
        sec.sh_degree = le16(sh + 40);
        if (sec.sh_degree > 2)
            fail(name, where + "sphericalHarmonicsDegree: " + std::to_string(sec.sh_degree) + " is not 0, 1 or 2");
        if (sec.count > sec.capacity)
            fail(name, where + "splatCount: " + std::to_string(sec.count) + " exceeds the section's capacity " +
                           std::to_string(sec.capacity));
        sec.stride = bytes_per_gaussian(h.level, sec.sh_degree);
        const std::uint64_t remaining = size - std::min<std::size_t>(at, size);
        const std::uint64_t lengths = 4ull * sec.partial;
        const std::uint64_t centres = std::uint64_t(sec.bucket_bytes) * sec.buckets;
        const std::uint64_t records = std::uint64_t(sec.stride) * sec.capacity;
        if (lengths > remaining || centres > remaining - lengths || records > remaining - lengths - centres)
            fail(name, where + "maxSplatCount: the section's " + std::to_string(sec.capacity) + " records of " +
                           std::to_string(sec.stride) + " bytes, " + std::to_string(sec.buckets) + " buckets and " +
                           std::to_string(sec.partial) + " partial bucket lengths run past the end of the file");
        sec.base = at;
        sec.data = at + static_cast<std::size_t>(lengths + centres);
        at = sec.data + static_cast<std::size_t>(records);
        if (h.level > 0 && sec.count > 0) {
            if (sec.bucket_bytes < 12)
                fail(name, where + "bucketStorageSizeBytes: " + std::to_string(sec.bucket_bytes) + " cannot hold a bucket centre (12)");
            if (!(std::isfinite(sec.block) && sec.block > 0))
                fail(name, where + "bucketBlockSize: " + std::to_string(sec.block) + " is not a positive size");
            if (sec.full > sec.buckets || sec.partial > sec.buckets - sec.full)
                fail(name, where + "fullBucketCount: " + std::to_string(sec.full) + " full and " + std::to_string(sec.partial) +
                               " partial buckets exceed the " + std::to_string(sec.buckets) + " buckets");
            const std::uint64_t in_full = std::uint64_t(sec.full) * sec.bucket_capacity;
            std::uint64_t in_partial = 0;
            for (std::uint32_t b = 0; b < sec.partial; ++b) in_partial += le32(data + sec.base + 4 * std::size_t(b));
            if (in_full + in_partial < sec.count)
                fail(name, where + "partiallyFilledBucketCount: the buckets hold " + std::to_string(in_full + in_partial) +
                               " Gaussians, the section " + std::to_string(sec.count));
        }
        total += sec.count;
        if (sec.count > 0) degree = std::max(degree, sec.sh_degree);
        sections.push_back(sec);
    }
    if (total != h.count)
        fail(name, "splatCount: the header says " + std::to_string(h.count) + " Gaussians, the sections hold " +
                       std::to_string(total));

    // Every record lies inside the file: the count is bounded by its size.
    GaussianCloud c(static_cast<std::size_t>(total), degree);
    const int k = c.sh_coeffs();
    const int per_sh = h.level == 0 ? 4 : h.level == 1 ? 2 : 1;
    const auto value = [&](const std::uint8_t* p, bool sh_value) -> float {
        if (h.level == 0) return lef32(p);
        if (h.level == 1 || !sh_value) return half_to_float(le16(p));
        return h.sh_min + (h.sh_max - h.sh_min) * (p[0] / 255.f);
    };
    const int scalar_bytes = h.level == 0 ? 4 : 2;
    const int colour_at = h.level == 0 ? 40 : 20, sh_at = h.level == 0 ? 44 : 24;
    std::size_t out = 0;
    for (std::size_t s = 0; s < sections.size(); ++s) {
        const Section& sec = sections[s];
        const float* centres = nullptr;
        std::vector<float> centre_copy;
        if (h.level > 0 && sec.count > 0) {
            centre_copy.resize(std::size_t(sec.buckets) * 3);
            for (std::size_t b = 0; b < sec.buckets; ++b)
                std::memcpy(&centre_copy[3 * b], data + sec.base + 4 * std::size_t(sec.partial) + b * sec.bucket_bytes, 12);
            centres = centre_copy.data();
        }
        const double step = h.level > 0 ? double(sec.block) / 2.0 / sec.quant_range : 0.0;
        std::uint32_t bucket = 0, partial = 0;
        std::uint64_t bucket_end = sec.bucket_capacity;  // exclusive end of the current bucket
        const std::uint64_t in_full = std::uint64_t(sec.full) * sec.bucket_capacity;
        for (std::uint32_t i = 0; i < sec.count; ++i, ++out) {
            const std::uint8_t* r = data + sec.data + std::size_t(i) * std::size_t(sec.stride);
            if (h.level == 0) {
                for (int a = 0; a < 3; ++a) c.means[3 * out + a] = lef32(r + 4 * a);
            } else {
                if (i < in_full) {
                    bucket = i / sec.bucket_capacity;
                } else {
                    if (i == in_full) bucket = sec.full, partial = 0, bucket_end = in_full + le32(data + sec.base);
                    while (i >= bucket_end) {  // past this partial bucket: the next one
                        ++bucket, ++partial;
                        if (partial >= sec.partial)
                            fail(name, "sections[" + std::to_string(s) + "].gaussians[" + std::to_string(i) +
                                           "]: beyond the last partially filled bucket");
                        bucket_end += le32(data + sec.base + 4 * std::size_t(partial));
                    }
                }
                for (int a = 0; a < 3; ++a)
                    c.means[3 * out + a] = static_cast<float>((double(le16(r + 2 * a)) - sec.quant_range) * step +
                                                              centres[3 * std::size_t(bucket) + a]);
            }
            for (int a = 0; a < 3; ++a) c.scales[3 * out + a] = value(r + 3 * scalar_bytes + a * scalar_bytes, false);
            for (int a = 0; a < 4; ++a) c.rotations[4 * out + a] = value(r + 6 * scalar_bytes + a * scalar_bytes, false);
            const std::uint8_t* rgba = r + colour_at;
            float* sh_out = &c.sh[out * std::size_t(k) * 3];
            for (int ch = 0; ch < 3; ++ch) sh_out[ch] = static_cast<float>(sh::color_to_dc(rgba[ch] / 255.0));
            c.opacities[out] = rgba[3] / 255.f;
            // Bands 1..d, channel-major within each band: band l's value (ch, m) at
            // band_start + ch * (2l + 1) + m; avsplat's coefficient l*l + m.
            int band_start = 0;
            for (int l = 1; l <= sec.sh_degree; ++l) {
                const int width = 2 * l + 1;
                for (int ch = 0; ch < 3; ++ch)
                    for (int m = 0; m < width; ++m)
                        sh_out[(l * l + m) * 3 + ch] = value(r + sh_at + (band_start + ch * width + m) * per_sh, true);
                band_start += 3 * width;
            }
        }
    }
    return c;
}

GaussianCloud read_ksplat(const std::string& path) {
    const std::uint64_t size = io::regular_file_size(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading");
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
    if (size && !in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size)))
        throw IOError(path + ": read failed");
    return parse_ksplat(bytes.data(), bytes.size(), path);
}

bool is_ksplat_file(const std::string& path) {
    try {
        const std::uint64_t size = io::regular_file_size(path);
        if (size < kHeaderSize + kSectionHeaderSize) return false;
        std::vector<std::uint8_t> head(kHeaderSize);
        std::ifstream in(path, std::ios::binary);
        if (!in || !in.read(reinterpret_cast<char*>(head.data()), kHeaderSize)) return false;
        Header h;
        if (!parse_header(head.data(), size, h).empty()) return false;
        if (head[2] != 0 || head[3] != 0) return false;
        for (std::size_t i = 44; i < kHeaderSize; ++i)
            if (head[i] != 0) return false;
        return h.count <= size / 24;
    } catch (const IOError&) {
        return false;
    }
}

}  // namespace avsplat
