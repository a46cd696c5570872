#include "avsplat/metrics/image_metrics.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

void check_finite(const float* v, std::size_t n, const char* fn, const char* name) {
    for (std::size_t i = 0; i < n; ++i)
        if (!std::isfinite(v[i]))
            throw std::invalid_argument(std::string(fn) + ": " + name + "[" + std::to_string(i) +
                                        "] is NaN or Inf");
}

void check_sizes(std::size_t na, std::size_t nb, std::size_t expected, const char* fn) {
    if (na != expected || nb != expected)
        throw std::invalid_argument(std::string(fn) + ": a has " + std::to_string(na) +
                                    " values and b " + std::to_string(nb) + ", expected " +
                                    std::to_string(expected));
}

constexpr int kWindow = 11;
constexpr int kHalf = kWindow / 2;

/// The normalised 1D Gaussian of the 3DGS SSIM window (sigma 1.5).
void gaussian_window(double* g) {
    double sum = 0.0;
    for (int k = 0; k < kWindow; ++k) {
        const double d = double(k - kHalf);
        g[k] = std::exp(-d * d / (2.0 * 1.5 * 1.5));
        sum += g[k];
    }
    for (int k = 0; k < kWindow; ++k) g[k] /= sum;
}

/// Same-size separable filtering with zero padding of an H x W plane (in place via `tmp`).
void filter(std::vector<double>& plane, std::vector<double>& tmp, int h, int w, const double* g) {
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            double s = 0.0;
            for (int k = 0; k < kWindow; ++k) {
                const int xx = x + k - kHalf;
                if (xx >= 0 && xx < w) s += g[k] * plane[std::size_t(y) * w + xx];
            }
            tmp[std::size_t(y) * w + x] = s;
        }
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) {
            double s = 0.0;
            for (int k = 0; k < kWindow; ++k) {
                const int yy = y + k - kHalf;
                if (yy >= 0 && yy < h) s += g[k] * tmp[std::size_t(yy) * w + x];
            }
            plane[std::size_t(y) * w + x] = s;
        }
}

}  // namespace

double psnr(const float* a, const float* b, std::size_t n, double max_value) {
    if (n == 0) throw std::invalid_argument("psnr: the images are empty");
    if (!(max_value > 0.0) || !std::isfinite(max_value))
        throw std::invalid_argument("psnr: max_value must be finite and > 0");
    check_finite(a, n, "psnr", "a");
    check_finite(b, n, "psnr", "b");
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const double d = double(a[i]) - double(b[i]);
        sum += d * d;
    }
    if (sum == 0.0) return std::numeric_limits<double>::infinity();
    return 10.0 * std::log10(max_value * max_value / (sum / double(n)));
}

double psnr(const std::vector<float>& a, const std::vector<float>& b, double max_value) {
    check_sizes(a.size(), b.size(), a.size(), "psnr");
    return psnr(a.data(), b.data(), a.size(), max_value);
}

double ssim(const float* a, const float* b, int height, int width, int channels) {
    if (height <= 0 || width <= 0 || channels <= 0)
        throw std::invalid_argument("ssim: height, width and channels must be > 0");
    const std::size_t plane = std::size_t(height) * std::size_t(width);
    check_finite(a, plane * channels, "ssim", "a");
    check_finite(b, plane * channels, "ssim", "b");
    double g[kWindow];
    gaussian_window(g);
    const double c1 = 0.01 * 0.01, c2 = 0.03 * 0.03;
    // Per-row sums added in row order: the total does not depend on the thread count.
    std::vector<double> row_sum(std::size_t(height), 0.0);
    std::vector<double> mu_a(plane), mu_b(plane), aa(plane), bb(plane), ab(plane), tmp(plane);
    for (int c = 0; c < channels; ++c) {
        for (std::size_t i = 0; i < plane; ++i) {
            const double x = a[i * channels + c], y = b[i * channels + c];
            mu_a[i] = x;
            mu_b[i] = y;
            aa[i] = x * x;
            bb[i] = y * y;
            ab[i] = x * y;
        }
        for (auto* p : {&mu_a, &mu_b, &aa, &bb, &ab}) filter(*p, tmp, height, width, g);
#pragma omp parallel for schedule(static)
        for (int y = 0; y < height; ++y) {
            double s = 0.0;
            for (std::size_t i = std::size_t(y) * width; i < std::size_t(y + 1) * width; ++i) {
                const double ma = mu_a[i], mb = mu_b[i];
                const double va = aa[i] - ma * ma, vb = bb[i] - mb * mb, cov = ab[i] - ma * mb;
                s += ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) /
                     ((ma * ma + mb * mb + c1) * (va + vb + c2));
            }
            row_sum[std::size_t(y)] += s;
        }
    }
    double total = 0.0;
    for (const double s : row_sum) total += s;
    return total / double(plane * channels);
}

double ssim(const std::vector<float>& a, const std::vector<float>& b, int height, int width,
            int channels) {
    if (height <= 0 || width <= 0 || channels <= 0)
        throw std::invalid_argument("ssim: height, width and channels must be > 0");
    check_sizes(a.size(), b.size(), std::size_t(height) * std::size_t(width) * std::size_t(channels), "ssim");
    return ssim(a.data(), b.data(), height, width, channels);
}

}  // namespace avsplat
