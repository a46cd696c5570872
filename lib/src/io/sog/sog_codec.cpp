// encode_sog / decode_sog: a GaussianCloud to and from the texels and codebooks of SOG version 2
// (the layout is described in avsplat/io/sog.h).
#include "avsplat/io/sog.h"

#include "avsplat/core/error.h"
#include "io/sog/codebook.h"
#include "io/sog/sog_meta.h"
#include "io/sog/webp_image.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace avsplat {

namespace {

using sog::RgbaImage;

constexpr double kSqrt2 = 1.4142135623730951;
/// Texels an image may hold beyond its count: any sensible layout pads far less (splat-transform
/// pads to multiples of 4: at most 4 sqrt(N) + 16).
constexpr std::size_t kSlackTexels = std::size_t(1) << 22;

double log_transform(double v) { return std::copysign(std::log1p(std::fabs(v)), v); }
double inverse_log_transform(double v) { return std::copysign(std::expm1(std::fabs(v)), v); }

std::uint8_t to_byte(double v) { return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L)); }

// Positions are stored as log1p(|x|) and scales as log(s) over bounds in meta.json; the reader
// refuses a bound beyond kMaxLog (e^88 is near float32's largest value), and so does the writer.
constexpr double kMaxLog = 88.0;

// The first Gaussian the reader would refuse for its position or scale: std::invalid_argument.
void check_storable(const GaussianCloud& c) {
    for (std::size_t i = 0; i < c.size(); ++i)
        for (int a = 0; a < 3; ++a) {
            const float m = c.means[3 * i + a];
            if (std::fabs(log_transform(m)) > kMaxLog)
                throw std::invalid_argument("write_sog: GaussianCloud.means[" + std::to_string(i) + "][" +
                                            std::to_string(a) + "] = " + std::to_string(m) +
                                            ": SOG stores positions within +-(e^88 - 1), about 1.65e38");
            const float s = c.scales[3 * i + a];
            if (s > 0 && std::log(double(s)) > kMaxLog)
                throw std::invalid_argument("write_sog: GaussianCloud.scales[" + std::to_string(i) + "][" +
                                            std::to_string(a) + "] = " + std::to_string(s) +
                                            ": SOG stores scales up to e^88, about 1.65e38");
        }
}

// Lossless WebP of a constant image is a few bytes per 10^4 texels, so a file of a few kilobytes
// can declare 2^26 Gaussians and ask for gigabytes. A SOG of real content stores 10 to 30 bytes
// per Gaussian in its images; a cloud may take at most kMaxExpansion times the bytes of the images
// (meta.json, a few kilobytes whatever the count, is not counted) beyond the first kFreeGaussians.
// The writer refuses what this refuses.
constexpr std::uint64_t kMaxExpansion = 1 << 16;
constexpr std::size_t kFreeGaussians = std::size_t(1) << 20;

void check_expansion(std::size_t count, int sh_degree, const SogFiles& files, const std::string& where) {
    if (count <= kFreeGaussians) return;
    std::uint64_t file_bytes = 0;
    for (const auto& f : files)
        if (f.first != "meta.json") file_bytes += f.second.size();
    const std::uint64_t floats = 14 + 3 * std::uint64_t(sh_coeffs_for_degree(sh_degree));
    const std::uint64_t memory = std::uint64_t(count) * floats * sizeof(float);
    if (memory / kMaxExpansion > file_bytes)
        throw IOError(where + ": \"count\" " + std::to_string(count) + " Gaussians of SH degree " +
                      std::to_string(sh_degree) + " take " + std::to_string(memory) + " bytes in memory, more than " +
                      std::to_string(kMaxExpansion) + " times the " + std::to_string(file_bytes) +
                      " bytes of the SOG's images; such nearly constant images are refused");
}

// The smallest multiple of 4 that is >= v.
std::size_t up4(std::size_t v) { return (v + 3) / 4 * 4; }

// splat-transform's texture size for n Gaussians: width the multiple of 4 at or above sqrt(n),
// height the multiple of 4 at or above n / width; at least 4 x 4 (an empty cloud).
std::pair<int, int> image_size(std::size_t n) {
    std::size_t s = static_cast<std::size_t>(std::sqrt(double(n)));
    while (s * s < n) ++s;
    while (s > 0 && (s - 1) * (s - 1) >= n) --s;
    const std::size_t w = std::max<std::size_t>(4, up4(s));
    const std::size_t h = std::max<std::size_t>(4, up4((n + w - 1) / w));
    if (w > std::size_t(sog::kMaxWebpSide) || h > std::size_t(sog::kMaxWebpSide))
        throw std::invalid_argument("write_sog: " + std::to_string(n) +
                                    " Gaussians need images larger than WebP's 16383 x 16383");
    return {int(w), int(h)};
}

// Z-order of the means over their bounding box, 21 bits per axis; ties keep the input order.
std::vector<std::size_t> morton_order(const GaussianCloud& c) {
    const std::size_t n = c.size();
    std::vector<std::size_t> order(n);
    for (std::size_t i = 0; i < n; ++i) order[i] = i;
    if (n < 2) return order;
    double lo[3], hi[3];
    for (int a = 0; a < 3; ++a) lo[a] = hi[a] = c.means[a];
    for (std::size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], double(c.means[3 * i + a]));
            hi[a] = std::max(hi[a], double(c.means[3 * i + a]));
        }
    auto spread = [](std::uint64_t v) {  // 21 bits -> every third bit
        v &= 0x1fffff;
        v = (v | v << 32) & 0x1f00000000ffffull;
        v = (v | v << 16) & 0x1f0000ff0000ffull;
        v = (v | v << 8) & 0x100f00f00f00f00full;
        v = (v | v << 4) & 0x10c30c30c30c30c3ull;
        v = (v | v << 2) & 0x1249249249249249ull;
        return v;
    };
    std::vector<std::pair<std::uint64_t, std::size_t>> keys(n);
    for (std::size_t i = 0; i < n; ++i) {
        std::uint64_t key = 0;
        for (int a = 0; a < 3; ++a) {
            const double range = hi[a] - lo[a];
            const double t = range > 0 ? (c.means[3 * i + a] - lo[a]) / range : 0.0;
            key |= spread(static_cast<std::uint64_t>(std::clamp(t * 2097151.0, 0.0, 2097151.0))) << a;
        }
        keys[i] = {key, i};
    }
    std::sort(keys.begin(), keys.end());
    for (std::size_t i = 0; i < n; ++i) order[i] = keys[i].second;
    return order;
}

RgbaImage blank(std::pair<int, int> size) {
    RgbaImage img;
    img.width = size.first;
    img.height = size.second;
    img.rgba.assign(img.pixels() * 4, 0);
    return img;
}

// splat-transform's palette size, min(64, 2^floor(log2(n / 1024))) * 1024: the largest power of
// two at or below n, at most 65536.
std::size_t default_palette(std::size_t n) {
    std::size_t p = 1;
    while (p * 2 <= n && p * 2 <= sog::kMaxPalette) p *= 2;
    return p;
}

}  // namespace

SogFiles encode_sog(const GaussianCloud& cloud, const SogWriteOptions& options) {
    validate(cloud);
    check_storable(cloud);
    if (options.iterations < 0 || options.iterations > 10000)
        throw std::invalid_argument("write_sog: iterations must be in 0..10000, got " +
                                    std::to_string(options.iterations));
    if (options.palette_size < 0 || std::size_t(options.palette_size) > sog::kMaxPalette)
        throw std::invalid_argument("write_sog: palette_size must be in 0..65536 (0: automatic), got " +
                                    std::to_string(options.palette_size));
    const std::size_t n = cloud.size();
    const int K = cloud.sh_coeffs();
    const auto size = image_size(n);
    std::vector<std::size_t> order = options.morton_order ? morton_order(cloud) : std::vector<std::size_t>(n);
    if (!options.morton_order)
        for (std::size_t i = 0; i < n; ++i) order[i] = i;

    sog::Meta meta;
    meta.count = n;
    SogFiles files;

    // means: 16 bits per axis over the bounds of the log-transformed positions.
    {
        double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
        for (std::size_t i = 0; i < n; ++i)
            for (int a = 0; a < 3; ++a) {
                const double v = log_transform(cloud.means[3 * i + a]);
                lo[a] = i == 0 ? v : std::min(lo[a], v);
                hi[a] = i == 0 ? v : std::max(hi[a], v);
            }
        RgbaImage low = blank(size), high = blank(size);
        for (std::size_t t = 0; t < n; ++t) {
            const std::size_t i = order[t];
            for (int a = 0; a < 3; ++a) {
                const double range = hi[a] - lo[a];
                const double u = range > 0 ? (log_transform(cloud.means[3 * i + a]) - lo[a]) / range : 0.0;
                const long q = std::clamp(std::lround(u * 65535.0), 0L, 65535L);
                low.rgba[4 * t + a] = static_cast<std::uint8_t>(q & 0xff);
                high.rgba[4 * t + a] = static_cast<std::uint8_t>(q >> 8);
            }
            low.rgba[4 * t + 3] = high.rgba[4 * t + 3] = 255;
        }
        for (int a = 0; a < 3; ++a) {
            meta.means_mins[a] = lo[a];
            meta.means_maxs[a] = hi[a];
        }
        meta.means_files = {"means_l.webp", "means_u.webp"};
        files["means_l.webp"] = sog::encode_webp(low, "means_l.webp");
        files["means_u.webp"] = sog::encode_webp(high, "means_u.webp");
    }

    // quats: smallest three, the largest component made positive and dropped.
    {
        RgbaImage img = blank(size);
        for (std::size_t t = 0; t < n; ++t) {
            const float* r = &cloud.rotations[4 * order[t]];
            double q[4] = {r[0], r[1], r[2], r[3]};
            const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
            int big = 0;
            for (int k = 1; k < 4; ++k)
                if (std::fabs(q[k]) > std::fabs(q[big])) big = k;
            const double s = (q[big] < 0 ? -kSqrt2 : kSqrt2) / norm;
            int ch = 0;
            for (int k = 0; k < 4; ++k)
                if (k != big) img.rgba[4 * t + ch++] = to_byte(255.0 * (q[k] * s * 0.5 + 0.5));
            img.rgba[4 * t + 3] = static_cast<std::uint8_t>(252 + big);
        }
        meta.quats_file = "quats.webp";
        files["quats.webp"] = sog::encode_webp(img, "quats.webp");
    }

    // scales: 256 shared log-scale levels (log 0 = -inf gets a level of its own).
    {
        std::vector<float> logs(3 * n);
        for (std::size_t i = 0; i < 3 * n; ++i) logs[i] = std::log(cloud.scales[i]);
        const sog::Codebook1D cb = sog::fit_codebook(logs);
        RgbaImage img = blank(size);
        for (std::size_t t = 0; t < n; ++t) {
            for (int a = 0; a < 3; ++a) img.rgba[4 * t + a] = cb.label(logs[3 * order[t] + a]);
            img.rgba[4 * t + 3] = 255;
        }
        meta.scales_codebook = cb.levels;
        meta.scales_file = "scales.webp";
        files["scales.webp"] = sog::encode_webp(img, "scales.webp");
    }

    // sh0: 256 shared degree-0 levels, opacity in alpha.
    {
        std::vector<float> dc(3 * n);
        for (std::size_t i = 0; i < n; ++i)
            for (int c = 0; c < 3; ++c) dc[3 * i + c] = cloud.sh[i * K * 3 + c];
        const sog::Codebook1D cb = sog::fit_codebook(dc);
        RgbaImage img = blank(size);
        for (std::size_t t = 0; t < n; ++t) {
            const std::size_t i = order[t];
            for (int c = 0; c < 3; ++c) img.rgba[4 * t + c] = cb.label(dc[3 * i + c]);
            img.rgba[4 * t + 3] = to_byte(255.0 * cloud.opacities[i]);
        }
        meta.sh0_codebook = cb.levels;
        meta.sh0_file = "sh0.webp";
        files["sh0.webp"] = sog::encode_webp(img, "sh0.webp");
    }

    // shN: a k-means palette of the SH-rest vectors, its values on 256 shared levels.
    if (cloud.sh_degree > 0) {
        const int coeffs = K - 1, dims = 3 * coeffs;
        std::vector<float> rest(n * dims);
        for (std::size_t i = 0; i < n; ++i)
            std::copy_n(&cloud.sh[i * K * 3 + 3], dims, rest.begin() + i * dims);
        const std::size_t k = options.palette_size > 0 ? std::size_t(options.palette_size) : default_palette(n);
        const sog::PaletteSearch how =
            options.exact_palette ? sog::PaletteSearch::Exhaustive : sog::PaletteSearch::Auto;
        const sog::Palette palette = sog::fit_palette(rest.data(), n, dims, k, options.iterations, options.seed, how);
        rest = {};
        const sog::Codebook1D cb = sog::fit_codebook(palette.centres);
        const std::size_t rows = std::max<std::size_t>(1, (palette.size + sog::kPaletteRow - 1) / sog::kPaletteRow);
        RgbaImage centres = blank({sog::kPaletteRow * coeffs, int(rows)});
        for (std::size_t e = 0; e < palette.size; ++e) {
            const std::size_t row = e / sog::kPaletteRow, col = (e % sog::kPaletteRow) * coeffs;
            for (int j = 0; j < coeffs; ++j) {
                std::uint8_t* px = &centres.rgba[4 * (row * centres.width + col + j)];
                for (int c = 0; c < 3; ++c) px[c] = cb.label(palette.centres[e * dims + 3 * j + c]);
                px[3] = 255;
            }
        }
        RgbaImage labels = blank(size);
        for (std::size_t t = 0; t < n; ++t) {
            const std::uint32_t l = palette.labels[order[t]];
            labels.rgba[4 * t] = static_cast<std::uint8_t>(l & 0xff);
            labels.rgba[4 * t + 1] = static_cast<std::uint8_t>(l >> 8);
            labels.rgba[4 * t + 3] = 255;
        }
        meta.sh_bands = cloud.sh_degree;
        meta.has_shn = true;
        meta.palette_count = std::max<std::size_t>(1, palette.size);
        meta.shn_codebook = cb.levels;
        meta.shn_files = {"shN_centroids.webp", "shN_labels.webp"};
        files["shN_centroids.webp"] = sog::encode_webp(centres, "shN_centroids.webp");
        files["shN_labels.webp"] = sog::encode_webp(labels, "shN_labels.webp");
    }
    files["meta.json"] = sog::format_meta(meta);
    check_expansion(n, cloud.sh_degree, files, "write_sog");
    return files;
}

namespace {

struct Decoder {
    const SogFiles& files;
    const std::string& name;
    const sog::Meta& meta;

    std::string where(const std::string& file) const { return name + "/" + file; }

    const std::string& bytes(const std::string& file, const char* field) const {
        auto it = files.find(file);
        if (it == files.end())
            throw IOError(where(file) + ": missing (named by meta.json \"" + field + "\")");
        return it->second;
    }

    // A per-Gaussian image holds at least `count` texels (checked from its header, before the
    // cloud of `count` Gaussians is allocated), and not absurdly more.
    void check_size(const std::string& file, const char* field) const {
        const auto [w, h] = sog::webp_size(bytes(file, field), where(file));
        if (std::size_t(w) * std::size_t(h) < meta.count)
            throw IOError(where(file) + ": " + std::to_string(w) + " x " + std::to_string(h) +
                          " texels hold fewer than the " + std::to_string(meta.count) +
                          " Gaussians of meta.json \"count\"");
    }

    RgbaImage per_gaussian(const std::string& file, const char* field) const {
        check_size(file, field);
        return sog::decode_webp(bytes(file, field), where(file), 2 * meta.count + kSlackTexels);
    }
};

}  // namespace

GaussianCloud decode_sog(const SogFiles& files, const std::string& name, const SogReadLimits& limits) {
    auto meta_it = files.find("meta.json");
    if (meta_it == files.end()) throw IOError(name + ": no meta.json");
    sog::Meta meta = sog::parse_meta(meta_it->second, name + "/meta.json", limits.max_gaussians);
    const Decoder d{files, name, meta};
    if (meta.version == 1 && meta.has_shn) {
        // Version 1 names no band count: the centroids image is 64 entries of 3, 8 or 15 texels.
        const std::string& file = meta.shn_files[0];
        const int width = sog::webp_size(d.bytes(file, "shN.files[0]"), d.where(file)).first;
        meta.sh_bands = width == 64 * 3 ? 1 : width == 64 * 8 ? 2 : width == 64 * 15 ? 3 : 0;
        if (meta.sh_bands == 0)
            throw IOError(d.where(file) + ": width " + std::to_string(width) +
                          " is not that of a SOG version 1 palette (192, 512 or 960 texels: SH bands 1, 2 or 3)");
        meta.palette_count = std::size_t(sog::kPaletteRow) *
                             std::size_t(sog::webp_size(d.bytes(file, "shN.files[0]"), d.where(file)).second);
    }
    const std::size_t n = meta.count;
    check_expansion(n, meta.sh_bands, files, name + "/meta.json");

    // Codebook entries (version 1: range ends) whose exp() overflows float would decode to
    // infinite scales.
    for (int a = 0; a < 3; ++a)
        if (meta.scales_maxs[a] > kMaxLog)
            throw IOError(name + "/meta.json: \"scales.maxs[" + std::to_string(a) + "]\" is " +
                          std::to_string(meta.scales_maxs[a]) + ", exp() of it overflows float32");
    for (std::size_t k = 0; k < meta.scales_codebook.size(); ++k)
        if (meta.scales_codebook[k] > kMaxLog)
            throw IOError(name + "/meta.json: \"scales.codebook[" + std::to_string(k) + "]\" is " +
                          std::to_string(meta.scales_codebook[k]) + ", exp() of it overflows float32");
    for (int a = 0; a < 3; ++a)
        if (std::fabs(meta.means_mins[a]) > kMaxLog || std::fabs(meta.means_maxs[a]) > kMaxLog)
            throw IOError(name + "/meta.json: \"means\" bounds of axis " + std::to_string(a) +
                          " exceed +-88: positions beyond float32's range");

    d.check_size(meta.means_files[0], "means.files[0]");
    d.check_size(meta.means_files[1], "means.files[1]");
    d.check_size(meta.quats_file, "quats.files[0]");
    d.check_size(meta.scales_file, "scales.files[0]");
    d.check_size(meta.sh0_file, "sh0.files[0]");
    if (meta.has_shn) d.check_size(meta.shn_files[1], "shN.files[1]");
    GaussianCloud c(n, meta.sh_bands);
    {
        const RgbaImage lo = d.per_gaussian(meta.means_files[0], "means.files[0]");
        const RgbaImage hi = d.per_gaussian(meta.means_files[1], "means.files[1]");
        for (int a = 0; a < 3; ++a) {
            const double base = meta.means_mins[a];
            const double range = meta.means_maxs[a] - base > 0 ? meta.means_maxs[a] - base : 1.0;
            for (std::size_t i = 0; i < n; ++i) {
                const unsigned q = lo.rgba[4 * i + a] | (unsigned(hi.rgba[4 * i + a]) << 8);
                c.means[3 * i + a] = static_cast<float>(inverse_log_transform(base + range * (q / 65535.0)));
            }
        }
    }
    {
        const RgbaImage img = d.per_gaussian(meta.quats_file, "quats.files[0]");
        for (std::size_t i = 0; i < n; ++i) {
            const std::uint8_t* px = &img.rgba[4 * i];
            if (px[3] < 252)
                throw IOError(d.where(meta.quats_file) + ": texel " + std::to_string(i) + ": alpha " +
                              std::to_string(px[3]) + " is not a largest-component tag (252..255)");
            const int big = px[3] - 252;
            double q[4], sum = 0;
            int ch = 0;
            for (int k = 0; k < 4; ++k) {
                if (k == big) continue;
                q[k] = (px[ch++] / 255.0 * 2.0 - 1.0) / kSqrt2;
                sum += q[k] * q[k];
            }
            q[big] = std::sqrt(std::max(0.0, 1.0 - sum));
            for (int k = 0; k < 4; ++k) c.rotations[4 * i + k] = static_cast<float>(q[k]);
        }
    }
    {
        const RgbaImage img = d.per_gaussian(meta.scales_file, "scales.files[0]");
        float level[3][256];
        for (int a = 0; a < 3; ++a)
            for (int k = 0; k < 256; ++k)
                level[a][k] = static_cast<float>(std::exp(
                    meta.version == 1 ? meta.scales_mins[a] + (meta.scales_maxs[a] - meta.scales_mins[a]) * (k / 255.0)
                                      : double(meta.scales_codebook[k])));
        for (std::size_t i = 0; i < n; ++i)
            for (int a = 0; a < 3; ++a) c.scales[3 * i + a] = level[a][img.rgba[4 * i + a]];
    }
    const int K = c.sh_coeffs();
    {
        const RgbaImage img = d.per_gaussian(meta.sh0_file, "sh0.files[0]");
        // Version 1: RGB linear over sh0's ranges, A the opacity's logit over the fourth range.
        float level[4][256];
        for (int ch = 0; ch < 4; ++ch)
            for (int k = 0; k < 256; ++k) {
                if (meta.version == 2) {
                    level[ch][k] = ch < 3 ? meta.sh0_codebook[k] : k / 255.f;
                    continue;
                }
                const double v = meta.sh0_mins[ch] + (meta.sh0_maxs[ch] - meta.sh0_mins[ch]) * (k / 255.0);
                level[ch][k] = static_cast<float>(ch < 3 ? v : 1.0 / (1.0 + std::exp(-v)));
            }
        for (std::size_t i = 0; i < n; ++i) {
            for (int ch = 0; ch < 3; ++ch) c.sh[i * K * 3 + ch] = level[ch][img.rgba[4 * i + ch]];
            c.opacities[i] = level[3][img.rgba[4 * i + 3]];
        }
    }
    if (meta.has_shn) {
        const int coeffs = K - 1;
        float shn_level[256];
        for (int k = 0; k < 256; ++k)
            shn_level[k] = meta.version == 1
                               ? static_cast<float>(meta.shn_min + (meta.shn_max - meta.shn_min) * (k / 255.0))
                               : meta.shn_codebook[k];
        const std::size_t max_rows = (meta.palette_count + sog::kPaletteRow - 1) / sog::kPaletteRow;
        const RgbaImage centres = sog::decode_webp(d.bytes(meta.shn_files[0], "shN.files[0]"),
                                                   d.where(meta.shn_files[0]),
                                                   std::size_t(sog::kPaletteRow) * coeffs * max_rows);
        if (centres.width != sog::kPaletteRow * coeffs)
            throw IOError(d.where(meta.shn_files[0]) + ": width " + std::to_string(centres.width) + " is not " +
                          std::to_string(sog::kPaletteRow * coeffs) + " (64 entries of " +
                          std::to_string(coeffs) + " texels for shN.bands " + std::to_string(meta.sh_bands) + ")");
        const std::size_t entries = std::min(meta.palette_count, std::size_t(centres.height) * sog::kPaletteRow);
        const RgbaImage labels = d.per_gaussian(meta.shn_files[1], "shN.files[1]");
        for (std::size_t i = 0; i < n; ++i) {
            const std::size_t l = labels.rgba[4 * i] | (std::size_t(labels.rgba[4 * i + 1]) << 8);
            if (l >= entries)
                throw IOError(d.where(meta.shn_files[1]) + ": texel " + std::to_string(i) + ": label " +
                              std::to_string(l) + " is outside the palette of " + std::to_string(entries) +
                              " entries");
            const std::size_t row = l / sog::kPaletteRow, col = (l % sog::kPaletteRow) * coeffs;
            for (int j = 0; j < coeffs; ++j) {
                const std::uint8_t* px = &centres.rgba[4 * (row * centres.width + col + j)];
                for (int ch = 0; ch < 3; ++ch) c.sh[i * K * 3 + 3 * (j + 1) + ch] = shn_level[px[ch]];
            }
        }
    }
    return c;
}

}  // namespace avsplat
