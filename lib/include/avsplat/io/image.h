// PNG output of rendered images (libpng; part of the core library).
//
// All images are row-major with `height` rows of `width` pixels. Values are stored as 8-bit:
// v -> round(255 clamp(v, 0, 1)), NaN -> 0. Every function throws std::invalid_argument for a
// non-positive size or a path that does not end in ".png" (any case), and avsplat::IOError
// naming the file when it cannot be written (the previous file is then left as it was).
#pragma once

#include <array>
#include <limits>
#include <string>

namespace avsplat {

/// Writes an H x W x 3 RGB image (e.g. RenderResult::color) as an 8-bit RGB PNG.
void write_color_png(const std::string& path, const float* rgb, int width, int height);

/// Writes an H x W image in [0, 1] (e.g. RenderResult::alpha) as an 8-bit grayscale PNG.
void write_alpha_png(const std::string& path, const float* alpha, int width, int height);

/// Writes an H x W depth map as an 8-bit RGB PNG coloured with the turbo colour map:
/// t = (depth - near) / (far - near) clamped to [0, 1]: near is dark blue (t = 0), then blue,
/// green, yellow, and far is dark red (t = 1). Pixels without a depth (depth <= 0 or not finite, as RenderResult::depth where
/// alpha is 0) are black. When `near` or `far` is not finite (the default) it is taken from
/// the smallest or largest valid depth; when far <= near every valid pixel gets t = 0.
void write_depth_png(const std::string& path, const float* depth, int width, int height,
                     float near = std::numeric_limits<float>::quiet_NaN(),
                     float far = std::numeric_limits<float>::quiet_NaN());

/// The turbo colour map (Mikhailov 2019) at t clamped to [0, 1] (NaN -> 0): RGB in [0, 1],
/// interpolated linearly between 33 samples of Google's 256-entry table (within 0.007 of it).
std::array<float, 3> turbo_colormap(float t);

}  // namespace avsplat
