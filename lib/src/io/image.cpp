#include "avsplat/io/image.h"

#include "avsplat/core/error.h"

#include "avsplat/io/atomic_file.h"

#include <png.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

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

// Encodes 8-bit pixels (channels 1 or 3) with libpng's simplified API, which reports errors
// through its return value and a message (no setjmp), then writes the file atomically.
void write_png(const char* fn, const std::string& path, const std::vector<std::uint8_t>& pixels, int width,
               int height, int channels) {
    png_image image{};
    image.version = PNG_IMAGE_VERSION;
    image.width = static_cast<png_uint_32>(width);
    image.height = static_cast<png_uint_32>(height);
    image.format = channels == 3 ? PNG_FORMAT_RGB : PNG_FORMAT_GRAY;
    png_alloc_size_t size = 0;
    const png_int_32 stride = width * channels;
    if (!png_image_write_to_memory(&image, nullptr, &size, 0, pixels.data(), stride, nullptr))
        throw IOError(path + ": " + fn + ": cannot encode the PNG: " + image.message);
    std::string bytes(size, '\0');
    if (!png_image_write_to_memory(&image, bytes.data(), &size, 0, pixels.data(), stride, nullptr))
        throw IOError(path + ": " + fn + ": cannot encode the PNG: " + image.message);
    png_image_free(&image);
    bytes.resize(size);
    try {
        write_file_atomically(path, bytes);
    } catch (const OutputError& e) {
        throw OutputError(std::string(fn) + ": cannot write " + e.what());
    }
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
    const std::size_t n = std::size_t(width) * std::size_t(height) * 3;
    std::vector<std::uint8_t> pixels(n);
    for (std::size_t i = 0; i < n; ++i) pixels[i] = to_byte(rgb[i]);
    write_png("write_color_png", path, pixels, width, height, 3);
}

void write_alpha_png(const std::string& path, const float* alpha, int width, int height) {
    check_args("write_alpha_png", path, alpha, width, height);
    const std::size_t n = std::size_t(width) * std::size_t(height);
    std::vector<std::uint8_t> pixels(n);
    for (std::size_t i = 0; i < n; ++i) pixels[i] = to_byte(alpha[i]);
    write_png("write_alpha_png", path, pixels, width, height, 1);
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
    std::vector<std::uint8_t> pixels(3 * n);
    for (std::size_t i = 0; i < n; ++i) {
        std::array<float, 3> c{0.0f, 0.0f, 0.0f};
        if (valid(depth[i])) c = turbo_colormap(span > 0.0 ? float((double(depth[i]) - lo) / span) : 0.0f);
        for (int k = 0; k < 3; ++k) pixels[3 * i + k] = to_byte(c[k]);
    }
    write_png("write_depth_png", path, pixels, width, height, 3);
}

}  // namespace avsplat
