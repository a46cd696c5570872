// decode_gaussians / encode_gaussians: AnySplat's activations between raw head features and
// Gaussians (see fusion/feature_decoder.h).
#include "avsplat/fusion/feature_decoder.h"

#include "core/invalid_samples.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

constexpr int kScaleChannels = 3, kRotationChannels = 4;

int sh_channels(const FeatureLayout& l) { return 3 * sh_coeffs_for_degree(l.sh_degree); }

// The largest log scale whose exponential is a finite float32 (log FLT_MAX, rounded down).
constexpr double kMaxLogScale = 88.72283905206835;

// sigmoid(x) without overflow for any finite x.
double sigmoid(double x) {
    if (x >= 0.0) return 1.0 / (1.0 + std::exp(-x));
    const double e = std::exp(x);
    return e / (1.0 + e);
}

bool finite(float x) { return std::isfinite(x); }

}  // namespace

int FeatureLayout::channels() const noexcept {
    return std::max({opacity + 1, scale + kScaleChannels, rotation + kRotationChannels,
                     sh + 3 * sh_coeffs_for_degree(std::clamp(sh_degree, 0, kMaxShDegree))});
}

void FeatureLayout::validate(int c) const {
    auto fail = [](const std::string& what) { throw std::invalid_argument("FeatureLayout." + what); };
    if (sh_degree < 0 || sh_degree > kMaxShDegree) fail("sh_degree: must be in 0..3");
    const struct {
        const char* name;
        int first, count;
    } fields[] = {{"opacity", opacity, 1},
                  {"scale", scale, kScaleChannels},
                  {"rotation", rotation, kRotationChannels},
                  {"sh", sh, sh_channels(*this)}};
    for (const auto& f : fields)
        if (f.first < 0) fail(std::string(f.name) + ": channel offset must be >= 0");
    for (std::size_t a = 0; a < 4; ++a)
        for (std::size_t b = a + 1; b < 4; ++b)
            if (fields[a].first < fields[b].first + fields[b].count && fields[b].first < fields[a].first + fields[a].count)
                fail(std::string(fields[b].name) + ": channels " + std::to_string(fields[b].first) + ".." +
                     std::to_string(fields[b].first + fields[b].count - 1) + " overlap " + fields[a].name + "'s " +
                     std::to_string(fields[a].first) + ".." + std::to_string(fields[a].first + fields[a].count - 1));
    if (c >= 0 && channels() > c)
        fail("channels: the layout needs " + std::to_string(channels()) + " feature channels, got " + std::to_string(c));
}

GaussianCloud decode_gaussians(const float* positions, std::size_t n, const float* features, int channels,
                               const FeatureLayout& layout, const float* confidence) {
    if (channels < 0) throw std::invalid_argument("decode_gaussians: channels must be >= 0");
    layout.validate(channels);
    if (n > 0 && (positions == nullptr || features == nullptr))
        throw std::invalid_argument("decode_gaussians: positions and features are required");
    const std::size_t C = static_cast<std::size_t>(channels);
    const int K = sh_coeffs_for_degree(layout.sh_degree);

    // The first bad sample in input order, whatever the thread count; then one message for it.
    auto bad = [&](std::size_t i) {
        for (int c = 0; c < 3; ++c)
            if (!finite(positions[3 * i + c])) return true;
        const float* f = features + i * C;
        for (std::size_t c = 0; c < C; ++c)
            if (!finite(f[c])) return true;
        if (confidence && !finite(confidence[i])) return true;
        for (int k = 0; k < kScaleChannels; ++k)
            if (f[layout.scale + k] > kMaxLogScale) return true;
        double q2 = 0.0;
        for (int k = 0; k < kRotationChannels; ++k) q2 += double(f[layout.rotation + k]) * f[layout.rotation + k];
        return !(q2 > 0.0);
    };
    const std::size_t first = first_bad_index(n, bad);
    if (first != kNoIndex) {
        const std::size_t i = first;
        const std::string at = "[" + std::to_string(i);
        for (int c = 0; c < 3; ++c)
            if (!finite(positions[3 * i + c]))
                throw std::invalid_argument("decode_gaussians: positions" + at + ", " + std::to_string(c) + "] is not finite");
        const float* f = features + i * C;
        for (std::size_t c = 0; c < C; ++c)
            if (!finite(f[c]))
                throw std::invalid_argument("decode_gaussians: features" + at + ", " + std::to_string(c) + "] is not finite");
        if (confidence && !finite(confidence[i]))
            throw std::invalid_argument("decode_gaussians: confidence" + at + "] is not finite");
        for (int k = 0; k < kScaleChannels; ++k)
            if (f[layout.scale + k] > kMaxLogScale)
                throw std::invalid_argument("decode_gaussians: features" + at + ", " + std::to_string(layout.scale + k) +
                                            "] = " + std::to_string(f[layout.scale + k]) +
                                            ": log scale overflows float32 (> 88.72)");
        throw std::invalid_argument("decode_gaussians: features" + at + ", " + std::to_string(layout.rotation) + ".." +
                                    std::to_string(layout.rotation + 3) + "]: quaternion of zero length");
    }

    GaussianCloud g(n, layout.sh_degree);
    if (confidence) g.confidence.assign(confidence, confidence + n);
#pragma omp parallel for schedule(static) if (n >= 4096)
    for (std::int64_t ii = 0; ii < static_cast<std::int64_t>(n); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        const float* f = features + i * C;
        for (int c = 0; c < 3; ++c) g.means[3 * i + c] = positions[3 * i + c];
        g.opacities[i] = static_cast<float>(sigmoid(f[layout.opacity]));
        for (int k = 0; k < kScaleChannels; ++k) g.scales[3 * i + k] = static_cast<float>(std::exp(double(f[layout.scale + k])));
        double q2 = 0.0;
        for (int k = 0; k < kRotationChannels; ++k) q2 += double(f[layout.rotation + k]) * f[layout.rotation + k];
        const double inv = 1.0 / std::sqrt(q2);
        for (int k = 0; k < kRotationChannels; ++k) g.rotations[4 * i + k] = static_cast<float>(f[layout.rotation + k] * inv);
        std::copy_n(f + layout.sh, 3 * K, &g.sh[i * 3 * K]);
    }
    return g;
}

std::vector<float> encode_gaussians(const GaussianCloud& cloud, const FeatureLayout& layout) {
    layout.validate();
    if (cloud.sh_degree != layout.sh_degree)
        throw std::invalid_argument("encode_gaussians: the cloud has SH degree " + std::to_string(cloud.sh_degree) +
                                    ", the layout " + std::to_string(layout.sh_degree));
    validate(cloud);
    const std::size_t n = cloud.size(), C = static_cast<std::size_t>(layout.channels());
    const int K = cloud.sh_coeffs();
    std::vector<float> out(n * C, 0.f);
#pragma omp parallel for schedule(static) if (n >= 4096)
    for (std::int64_t ii = 0; ii < static_cast<std::int64_t>(n); ++ii) {
        const auto i = static_cast<std::size_t>(ii);
        float* f = &out[i * C];
        const double o = std::clamp(double(cloud.opacities[i]), 1e-6, 1.0 - 1e-6);
        f[layout.opacity] = static_cast<float>(std::log(o) - std::log1p(-o));
        for (int k = 0; k < kScaleChannels; ++k)
            f[layout.scale + k] = static_cast<float>(std::log(std::max(double(cloud.scales[3 * i + k]), double(FLT_MIN))));
        double q2 = 0.0;
        for (int k = 0; k < kRotationChannels; ++k) q2 += double(cloud.rotations[4 * i + k]) * cloud.rotations[4 * i + k];
        const double inv = 1.0 / std::sqrt(q2);
        for (int k = 0; k < kRotationChannels; ++k) f[layout.rotation + k] = static_cast<float>(cloud.rotations[4 * i + k] * inv);
        std::copy_n(&cloud.sh[i * 3 * K], 3 * K, f + layout.sh);
    }
    return out;
}

}  // namespace avsplat
