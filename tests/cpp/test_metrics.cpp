// Tests of psnr and ssim against values computed here: PSNR by hand, SSIM by a direct
// (non-separable) 11 x 11 windowed sum with zero padding, the definition the 3DGS evaluation
// code implements with a 2D convolution.
#include "avsplat/metrics/metrics.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

using Catch::Matchers::Contains;

namespace {

std::vector<float> random_image(int h, int w, int c, std::uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<float> v(std::size_t(h) * w * c);
    for (float& x : v) x = u(rng);
    return v;
}

/// SSIM of H x W x C images by direct summation over the 11 x 11 window.
double direct_ssim(const std::vector<float>& a, const std::vector<float>& b, int h, int w, int ch) {
    double g[11], sum = 0;
    for (int k = 0; k < 11; ++k) sum += g[k] = std::exp(-(k - 5.0) * (k - 5.0) / (2 * 1.5 * 1.5));
    for (double& x : g) x /= sum;
    const double c1 = 1e-4, c2 = 9e-4;
    double total = 0;
    for (int c = 0; c < ch; ++c)
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {
                double ma = 0, mb = 0, aa = 0, bb = 0, ab = 0;
                for (int dy = -5; dy <= 5; ++dy)
                    for (int dx = -5; dx <= 5; ++dx) {
                        const int yy = y + dy, xx = x + dx;
                        if (yy < 0 || yy >= h || xx < 0 || xx >= w) continue;  // zero padding
                        const double wgt = g[dy + 5] * g[dx + 5];
                        const double va = a[(std::size_t(yy) * w + xx) * ch + c], vb = b[(std::size_t(yy) * w + xx) * ch + c];
                        ma += wgt * va;
                        mb += wgt * vb;
                        aa += wgt * va * va;
                        bb += wgt * vb * vb;
                        ab += wgt * va * vb;
                    }
                const double sa = aa - ma * ma, sb = bb - mb * mb, sab = ab - ma * mb;
                total += (2 * ma * mb + c1) * (2 * sab + c2) / ((ma * ma + mb * mb + c1) * (sa + sb + c2));
            }
    return total / (double(h) * w * ch);
}

}  // namespace

TEST_CASE("psnr matches hand-computed values", "[metrics]") {
    std::vector<float> a(300, 0.25f), b(300, 0.35f);
    // MSE = 0.01 -> 10 log10(1 / 0.01) = 20 dB; with max_value 2: 10 log10(4 / 0.01).
    CHECK(avsplat::psnr(a, b) == Approx(20.0).epsilon(1e-6));
    CHECK(avsplat::psnr(a, b, 2.0) == Approx(10 * std::log10(400.0)).epsilon(1e-6));
    // Half the values off by 0.2, half exact: MSE = 0.02.
    for (std::size_t i = 0; i < 300; i += 2) b[i] = 0.25f;
    for (std::size_t i = 1; i < 300; i += 2) b[i] = 0.45f;
    CHECK(avsplat::psnr(a, b) == Approx(10 * std::log10(1 / 0.02)).epsilon(1e-6));
    CHECK(avsplat::psnr(a, a) == std::numeric_limits<double>::infinity());
}

TEST_CASE("psnr rejects bad input", "[metrics]") {
    std::vector<float> a(10, 0.5f), b(11, 0.5f), empty;
    CHECK_THROWS_AS(avsplat::psnr(a, b), std::invalid_argument);
    CHECK_THROWS_AS(avsplat::psnr(empty, empty), std::invalid_argument);
    CHECK_THROWS_AS(avsplat::psnr(a, a, 0.0), std::invalid_argument);
    std::vector<float> c = a;
    c[7] = std::numeric_limits<float>::quiet_NaN();
    CHECK_THROWS_WITH(avsplat::psnr(a, c), Contains("b[7]"));
}

TEST_CASE("ssim matches the direct windowed definition with zero padding", "[metrics]") {
    const int h = GENERATE(1, 9, 23), w = GENERATE(4, 17), ch = GENERATE(1, 3);
    const std::vector<float> a = random_image(h, w, ch, 1);
    std::vector<float> b = a;
    std::mt19937 rng(2);
    std::normal_distribution<float> noise(0.0f, 0.1f);
    for (float& x : b) x = std::min(1.0f, std::max(0.0f, x + noise(rng)));
    const double s = avsplat::ssim(a, b, h, w, ch);
    CHECK(s == Approx(direct_ssim(a, b, h, w, ch)).margin(1e-12));
    CHECK(s < 1.0);
    CHECK(avsplat::ssim(b, a, h, w, ch) == Approx(s).margin(1e-15));
    CHECK(avsplat::ssim(a, a, h, w, ch) == Approx(1.0).margin(1e-15));
}

TEST_CASE("ssim decreases as noise grows", "[metrics]") {
    const std::vector<float> a = random_image(32, 32, 3, 5);
    double previous = 1.0;
    for (const float sigma : {0.01f, 0.05f, 0.2f}) {
        std::vector<float> b = a;
        std::mt19937 rng(6);
        std::normal_distribution<float> noise(0.0f, sigma);
        for (float& x : b) x += noise(rng);
        const double s = avsplat::ssim(a, b, 32, 32, 3);
        CHECK(s < previous);
        previous = s;
    }
}

TEST_CASE("ssim rejects bad input", "[metrics]") {
    const std::vector<float> a = random_image(4, 4, 3, 1);
    CHECK_THROWS_AS(avsplat::ssim(a, a, 4, 4, 1), std::invalid_argument);  // size mismatch
    CHECK_THROWS_AS(avsplat::ssim(a, a, 0, 4, 3), std::invalid_argument);
    std::vector<float> b = a;
    b[5] = std::numeric_limits<float>::infinity();
    CHECK_THROWS_WITH(avsplat::ssim(a, b, 4, 4, 3), Contains("b[5]"));
}
