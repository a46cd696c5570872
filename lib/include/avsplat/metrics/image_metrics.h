// Image quality metrics, as the 3DGS evaluation code computes them.
//
// Images are row-major H x W x C float arrays (C interleaved channels, C = 3 for RGB) with
// values in [0, 1]; the SSIM constants assume that data range. Everything is accumulated in
// double and summed in a fixed order, so results do not depend on the number of threads.
#pragma once

#include <cstddef>
#include <vector>

namespace avsplat {

/// Peak signal-to-noise ratio 10 log10(max_value^2 / MSE) in dB, the MSE taken over all n
/// values of a and b; +infinity when they are equal. Throws std::invalid_argument when n is 0,
/// max_value is not finite and > 0, or a value is NaN/Inf (naming the array and index).
double psnr(const float* a, const float* b, std::size_t n, double max_value = 1.0);

/// psnr over two arrays of the same size (std::invalid_argument otherwise).
double psnr(const std::vector<float>& a, const std::vector<float>& b, double max_value = 1.0);

/// Structural similarity of two H x W x C images as the 3DGS evaluation code (utils/loss_utils
/// ssim): Gaussian window of 11 x 11 pixels with sigma 1.5, each channel filtered separately
/// with zero padding (same-size output), C1 = 0.01^2, C2 = 0.03^2, and the SSIM map averaged
/// over all pixels and channels. Throws std::invalid_argument when height, width or channels
/// is not positive or a value is NaN/Inf.
double ssim(const float* a, const float* b, int height, int width, int channels);

/// ssim over two arrays of size height * width * channels (std::invalid_argument otherwise).
double ssim(const std::vector<float>& a, const std::vector<float>& b, int height, int width,
            int channels = 3);

}  // namespace avsplat
