#include "avsplat/io/image.h"

#include "avsplat/error.h"

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

}  // namespace

std::array<float, 3> turbo_colormap(float t) {
    const double x = std::isnan(t) ? 0.0 : std::clamp(double(t), 0.0, 1.0);
    const double r = 0.13572138 + x * (4.61539260 + x * (-42.66032258 + x * (132.13108234 + x * (-152.94239396 + x * 59.28637943))));
    const double g = 0.09140261 + x * (2.19418839 + x * (4.84296658 + x * (-14.18503333 + x * (4.27729857 + x * 2.82956604))));
    const double b = 0.10667330 + x * (12.64194608 + x * (-60.58204836 + x * (110.36276771 + x * (-89.90310912 + x * 27.34824973))));
    return {float(std::clamp(r, 0.0, 1.0)), float(std::clamp(g, 0.0, 1.0)), float(std::clamp(b, 0.0, 1.0))};
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
