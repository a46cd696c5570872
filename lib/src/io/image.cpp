#include "avsplat/io/image.h"

#include "avsplat/core/error.h"

#include <open3d/geometry/Image.h>
#include <open3d/io/ImageIO.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace avsplat {

namespace {

void check_args(const char* fn, const std::string& path, const float* data, int width, int height) {
    if (width <= 0 || height <= 0)
        throw std::invalid_argument(std::string(fn) + ": width and height must be > 0");
    if (data == nullptr) throw std::invalid_argument(std::string(fn) + ": the image data is null");
    std::string ext = path.size() >= 4 ? path.substr(path.size() - 4) : std::string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    if (ext != ".png") throw std::invalid_argument(std::string(fn) + ": path must end in .png: " + path);
}

std::uint8_t to_byte(float v) {
    if (!(v > 0.0f)) return 0;  // also NaN
    if (v >= 1.0f) return 255;
    return std::uint8_t(std::lround(double(v) * 255.0));
}

void write(const char* fn, const std::string& path, const open3d::geometry::Image& image) {
    if (!open3d::io::WriteImage(path, image))
        throw IOError(std::string(fn) + ": cannot write " + path);
}

// The turbo colour map (Copyright 2019 Google LLC, Apache License 2.0; Mikhailov 2019) sampled
// at t = k / 32 from its 256-entry table. Linear interpolation between these samples is within
// 0.007 of the full table.
constexpr int kTurboSamples = 33;
constexpr float kTurbo[kTurboSamples][3] = {
    {0.1900f, 0.0718f, 0.2322f}, {0.2249f, 0.1632f, 0.4502f}, {0.2509f, 0.2517f, 0.6324f},
    {0.2680f, 0.3373f, 0.7790f}, {0.2762f, 0.4199f, 0.8897f}, {0.2755f, 0.4996f, 0.9648f},
    {0.2594f, 0.5777f, 0.9986f}, {0.2153f, 0.6567f, 0.9806f}, {0.1602f, 0.7332f, 0.9252f},
    {0.1130f, 0.8034f, 0.8482f}, {0.0927f, 0.8634f, 0.7655f}, {0.1179f, 0.9101f, 0.6900f},
    {0.1922f, 0.9474f, 0.5993f}, {0.2992f, 0.9758f, 0.4953f}, {0.4210f, 0.9935f, 0.3912f},
    {0.5400f, 0.9991f, 0.3005f}, {0.6384f, 0.9910f, 0.2365f}, {0.7205f, 0.9669f, 0.2073f},
    {0.7994f, 0.9277f, 0.2042f}, {0.8704f, 0.8768f, 0.2146f}, {0.9290f, 0.8173f, 0.2261f},
    {0.9707f, 0.7523f, 0.2262f}, {0.9921f, 0.6810f, 0.2059f}, {0.9963f, 0.5952f, 0.1724f},
    {0.9853f, 0.5018f, 0.1324f}, {0.9610f, 0.4084f, 0.0921f}, {0.9253f, 0.3229f, 0.0577f},
    {0.8797f, 0.2521f, 0.0349f}, {0.8230f, 0.1909f, 0.0195f}, {0.7547f, 0.1367f, 0.0093f},
    {0.6747f, 0.0895f, 0.0045f}, {0.5830f, 0.0492f, 0.0049f}, {0.4796f, 0.0158f, 0.0106f},
};

}  // namespace

std::array<float, 3> turbo_colormap(float t) {
    const double x = std::isnan(t) ? 0.0 : std::clamp(double(t), 0.0, 1.0) * (kTurboSamples - 1);
    const int k = std::min(int(x), kTurboSamples - 2);
    const double f = x - k;
    std::array<float, 3> c;
    for (int ch = 0; ch < 3; ++ch) c[ch] = float((1.0 - f) * kTurbo[k][ch] + f * kTurbo[k + 1][ch]);
    return c;
}

void write_color_png(const std::string& path, const float* rgb, int width, int height) {
    check_args("write_color_png", path, rgb, width, height);
    open3d::geometry::Image image;
    image.Prepare(width, height, 3, 1);
    const std::size_t n = std::size_t(width) * std::size_t(height) * 3;
    for (std::size_t i = 0; i < n; ++i) image.data_[i] = to_byte(rgb[i]);
    write("write_color_png", path, image);
}

void write_alpha_png(const std::string& path, const float* alpha, int width, int height) {
    check_args("write_alpha_png", path, alpha, width, height);
    open3d::geometry::Image image;
    image.Prepare(width, height, 1, 1);
    const std::size_t n = std::size_t(width) * std::size_t(height);
    for (std::size_t i = 0; i < n; ++i) image.data_[i] = to_byte(alpha[i]);
    write("write_alpha_png", path, image);
}

void write_depth_png(const std::string& path, const float* depth, int width, int height, float near,
                     float far) {
    check_args("write_depth_png", path, depth, width, height);
    const std::size_t n = std::size_t(width) * std::size_t(height);
    auto valid = [](float d) { return std::isfinite(d) && d > 0.0f; };
    float lo = near, hi = far;
    if (!std::isfinite(lo) || !std::isfinite(hi)) {
        float dmin = std::numeric_limits<float>::infinity(), dmax = -dmin;
        for (std::size_t i = 0; i < n; ++i)
            if (valid(depth[i])) {
                dmin = std::min(dmin, depth[i]);
                dmax = std::max(dmax, depth[i]);
            }
        if (!std::isfinite(lo)) lo = dmin;
        if (!std::isfinite(hi)) hi = dmax;
    }
    const double span = double(hi) - double(lo);
    open3d::geometry::Image image;
    image.Prepare(width, height, 3, 1);
    for (std::size_t i = 0; i < n; ++i) {
        std::array<float, 3> c{0.0f, 0.0f, 0.0f};
        if (valid(depth[i])) c = turbo_colormap(span > 0.0 ? float((double(depth[i]) - lo) / span) : 0.0f);
        for (int k = 0; k < 3; ++k) image.data_[3 * i + k] = to_byte(c[k]);
    }
    write("write_depth_png", path, image);
}

}  // namespace avsplat
