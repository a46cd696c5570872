// Tests of the PNG writers: each file is read back with Open3D's own reader and compared with
// the 8-bit values expected from the documented rules.
#include "avsplat/core/error.h"
#include "avsplat/io/image.h"

#include <catch2/catch.hpp>
#include <open3d/geometry/Image.h>
#include <open3d/io/ImageIO.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

using Catch::Matchers::Contains;

namespace {

std::string tmp_png(const std::string& name) {
    const auto dir = std::filesystem::temp_directory_path() / "avsplat_test_image_io";
    std::filesystem::create_directories(dir);
    return (dir / name).string();
}

open3d::geometry::Image read_back(const std::string& path) {
    open3d::geometry::Image image;
    REQUIRE(open3d::io::ReadImage(path, image));
    return image;
}

/// The documented 8-bit rule: round(255 clamp(v, 0, 1)), NaN -> 0.
int byte(double v) {
    if (!(v > 0)) return 0;
    if (v >= 1) return 255;
    return int(std::lround(v * 255.0));
}

}  // namespace

TEST_CASE("write_color_png stores clamped, rounded 8-bit RGB", "[image_io]") {
    const int w = 23, h = 11;
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(-0.2f, 1.2f);
    std::vector<float> rgb(std::size_t(w) * h * 3);
    for (float& v : rgb) v = u(rng);
    rgb[5] = std::numeric_limits<float>::quiet_NaN();
    const std::string path = tmp_png("color.png");
    avsplat::write_color_png(path, rgb.data(), w, h);
    const auto image = read_back(path);
    REQUIRE(image.width_ == w);
    REQUIRE(image.height_ == h);
    REQUIRE(image.num_of_channels_ == 3);
    REQUIRE(image.bytes_per_channel_ == 1);
    for (std::size_t i = 0; i < rgb.size(); ++i) REQUIRE(int(image.data_[i]) == byte(rgb[i]));
}

TEST_CASE("write_alpha_png stores an 8-bit grayscale image", "[image_io]") {
    const int w = 7, h = 5;
    std::vector<float> alpha(std::size_t(w) * h);
    for (std::size_t i = 0; i < alpha.size(); ++i) alpha[i] = float(i) / float(alpha.size() - 1);
    const std::string path = tmp_png("alpha.PNG");
    avsplat::write_alpha_png(path, alpha.data(), w, h);
    const auto image = read_back(path);
    REQUIRE(image.num_of_channels_ == 1);
    REQUIRE(image.width_ == w);
    for (std::size_t i = 0; i < alpha.size(); ++i) REQUIRE(int(image.data_[i]) == byte(alpha[i]));
    CHECK(int(image.data_[0]) == 0);
    CHECK(int(image.data_[alpha.size() - 1]) == 255);
}

TEST_CASE("write_depth_png maps depth to the turbo colour map, invalid pixels black", "[image_io]") {
    const int w = 12, h = 3;
    std::vector<float> depth(std::size_t(w) * h);
    for (int x = 0; x < w; ++x) {
        depth[std::size_t(x)] = 2.0f + 0.5f * float(x);  // 2 .. 7.5
        depth[std::size_t(w + x)] = 0.0f;                 // no depth
        depth[std::size_t(2 * w + x)] = x % 2 ? std::numeric_limits<float>::quiet_NaN() : 10.0f;
    }
    auto expect = [](double t) {
        const auto c = avsplat::turbo_colormap(float(t));
        return std::vector<int>{byte(c[0]), byte(c[1]), byte(c[2])};
    };
    auto pixel = [](const open3d::geometry::Image& im, std::size_t k) {
        return std::vector<int>{im.data_[3 * k], im.data_[3 * k + 1], im.data_[3 * k + 2]};
    };
    SECTION("near and far from the valid range (2 .. 10)") {
        const std::string path = tmp_png("depth_auto.png");
        avsplat::write_depth_png(path, depth.data(), w, h);
        const auto im = read_back(path);
        REQUIRE(im.num_of_channels_ == 3);
        for (int x = 0; x < w; ++x) {
            CHECK(pixel(im, std::size_t(x)) == expect((2.0 + 0.5 * x - 2.0) / 8.0));
            CHECK(pixel(im, std::size_t(w + x)) == std::vector<int>{0, 0, 0});
            CHECK(pixel(im, std::size_t(2 * w + x)) == (x % 2 ? std::vector<int>{0, 0, 0} : expect(1.0)));
        }
    }
    SECTION("given near and far clamp") {
        const std::string path = tmp_png("depth_given.png");
        avsplat::write_depth_png(path, depth.data(), w, h, 3.0f, 5.0f);
        const auto im = read_back(path);
        for (int x = 0; x < w; ++x)
            CHECK(pixel(im, std::size_t(x)) == expect(std::clamp((2.0 + 0.5 * x - 3.0) / 2.0, 0.0, 1.0)));
    }
}

TEST_CASE("turbo_colormap interpolates the turbo table", "[image_io]") {
    // Entries 0, 128 and 255 of Google's 256-entry turbo table.
    const double table[3][4] = {{0.0, 0.18995, 0.07176, 0.23217},
                                {128.0 / 255.0, 0.64362, 0.98999, 0.23356},
                                {1.0, 0.47960, 0.01583, 0.01055}};
    for (const auto& row : table) {
        const auto c = avsplat::turbo_colormap(float(row[0]));
        for (int ch = 0; ch < 3; ++ch) CHECK(c[ch] == Approx(row[1 + ch]).margin(0.007));
    }
    CHECK(avsplat::turbo_colormap(-3.0f) == avsplat::turbo_colormap(0.0f));
    CHECK(avsplat::turbo_colormap(7.0f) == avsplat::turbo_colormap(1.0f));
    CHECK(avsplat::turbo_colormap(std::numeric_limits<float>::quiet_NaN()) == avsplat::turbo_colormap(0.0f));
    for (int i = 0; i <= 1000; ++i)
        for (const float v : avsplat::turbo_colormap(float(i) / 1000.0f)) REQUIRE((v >= 0.0f && v <= 1.0f));
}

TEST_CASE("PNG writers reject bad arguments and report unwritable files", "[image_io]") {
    const std::vector<float> rgb(12, 0.5f);
    CHECK_THROWS_AS(avsplat::write_color_png(tmp_png("x.jpg"), rgb.data(), 2, 2), std::invalid_argument);
    CHECK_THROWS_AS(avsplat::write_color_png(tmp_png("x.png"), rgb.data(), 0, 2), std::invalid_argument);
    CHECK_THROWS_AS(avsplat::write_alpha_png(tmp_png("x.png"), nullptr, 2, 2), std::invalid_argument);
    CHECK_THROWS_WITH(avsplat::write_color_png("/nonexistent_dir_avsplat/x.png", rgb.data(), 2, 2),
                      Contains("/nonexistent_dir_avsplat/x.png"));
    CHECK_THROWS_AS(avsplat::write_depth_png("/nonexistent_dir_avsplat/x.png", rgb.data(), 2, 2),
                    avsplat::IOError);
}
