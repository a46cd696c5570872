#include "avsplat/core/error.h"
#include "avsplat/io/colmap.h"

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <cstdint>
#include <filesystem>
#include <fstream>

using avsplat::Camera;

namespace {

std::string model_dir(const std::string& name) {
    const std::string d = std::string(AVSPLAT_TEST_TMP) + "/" + name;
    std::filesystem::remove_all(d);
    std::filesystem::create_directories(d);
    return d;
}

void write_text(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

template <class T>
void put(std::ofstream& f, T v) {
    f.write(reinterpret_cast<const char*>(&v), sizeof v);
}

struct BinCamera {
    std::uint32_t id;
    std::int32_t model;
    std::uint64_t w, h;
    std::vector<double> params;
};
struct BinImage {
    std::uint32_t id;
    double q[4], t[3];
    std::uint32_t camera;
    std::string name;
    std::uint64_t points;
};

void write_bin(const std::string& dir, const std::vector<BinCamera>& cams, const std::vector<BinImage>& imgs) {
    std::ofstream c(dir + "/cameras.bin", std::ios::binary);
    put<std::uint64_t>(c, cams.size());
    for (const auto& k : cams) {
        put(c, k.id);
        put(c, k.model);
        put(c, k.w);
        put(c, k.h);
        for (double p : k.params) put(c, p);
    }
    std::ofstream i(dir + "/images.bin", std::ios::binary);
    put<std::uint64_t>(i, imgs.size());
    for (const auto& m : imgs) {
        put(i, m.id);
        for (double v : m.q) put(i, v);
        for (double v : m.t) put(i, v);
        put(i, m.camera);
        i.write(m.name.c_str(), std::streamsize(m.name.size() + 1));
        put(i, m.points);
        for (std::uint64_t p = 0; p < m.points; ++p) {
            put(i, 1.5);
            put(i, 2.5);
            put<std::int64_t>(i, -1);
        }
    }
}

// Hand-computed pose: a quarter turn about y. q = (cos 45, 0, sin 45, 0) rotates x to -z and z to
// x, so R = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]; with t = (1, 2, 3) the centre is -R^T t = (3, -2, -1).
const double kH = std::sqrt(0.5);

void check_quarter_turn(const Camera& c) {
    Eigen::Matrix4d expected;
    expected << 0, 0, 1, 1,  //
        0, 1, 0, 2,          //
        -1, 0, 0, 3,         //
        0, 0, 0, 1;
    CHECK((c.world_to_camera - expected).norm() < 1e-12);
    CHECK((c.position() - Eigen::Vector3d(3, -2, -1)).norm() < 1e-12);
}

}  // namespace

TEST_CASE("read_colmap_cameras reads a text model with PINHOLE and SIMPLE_PINHOLE cameras", "[colmap]") {
    const std::string d = model_dir("colmap_text");
    write_text(d + "/cameras.txt",
               "# Camera list with one line of data per camera:\n"
               "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
               "1 PINHOLE 640 480 500 510 320.5 240.5\n"
               "2 SIMPLE_PINHOLE 320 200 300 160 100\n");
    write_text(d + "/images.txt",
               "# Image list with two lines of data per image:\n"
               "3 " + std::to_string(kH) + " 0 " + std::to_string(kH) + " 0 1 2 3 1 left.jpg\n"
               "100.0 200.0 -1 110.0 210.0 5\n"
               "7 2 0 0 0 0 0 0 2 right.jpg\n"  // unnormalised identity quaternion
               "\n");
    for (const std::string& path : {d, d + "/cameras.txt", d + "/images.txt"}) {
        const auto cams = avsplat::read_colmap_cameras(path);
        REQUIRE(cams.size() == 2);
        CHECK(cams[0].name == "left.jpg");
        CHECK(cams[0].fx == 500.0);
        CHECK(cams[0].fy == 510.0);
        CHECK(cams[0].cx == 320.5);
        CHECK(cams[0].cy == 240.5);
        CHECK(cams[0].width == 640);
        CHECK(cams[0].height == 480);
        check_quarter_turn(cams[0]);
        CHECK(cams[1].name == "right.jpg");
        CHECK(cams[1].fx == 300.0);
        CHECK(cams[1].fy == 300.0);
        CHECK(cams[1].cx == 160.0);
        CHECK(cams[1].cy == 100.0);
        CHECK(cams[1].world_to_camera.isIdentity(1e-15));
    }
    CHECK(avsplat::is_colmap_model(d));
    CHECK_FALSE(avsplat::is_colmap_model(d + "/nothing.json"));
}

TEST_CASE("read_colmap_cameras keeps an image whose 2D point line is empty", "[colmap]") {
    const std::string d = model_dir("colmap_empty_points");
    write_text(d + "/cameras.txt", "1 PINHOLE 10 10 5 5 5 5\n");
    write_text(d + "/images.txt", "1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 1 1 b.png\n\n");
    const auto cams = avsplat::read_colmap_cameras(d);
    REQUIRE(cams.size() == 2);
    CHECK(cams[1].name == "b.png");
    CHECK(cams[1].world_to_camera(2, 3) == 1.0);
}

TEST_CASE("read_colmap_cameras reads a binary model", "[colmap]") {
    const std::string d = model_dir("colmap_binary");
    write_bin(d, {{4, 1, 640, 480, {500, 510, 320.5, 240.5}}, {9, 0, 320, 200, {300, 160, 100}}},
              {{3, {kH, 0, kH, 0}, {1, 2, 3}, 4, "left.jpg", 3}, {5, {1, 0, 0, 0}, {0, 0, 0}, 9, "right.jpg", 0}});
    const auto cams = avsplat::read_colmap_cameras(d + "/images.bin");
    REQUIRE(cams.size() == 2);
    CHECK(cams[0].name == "left.jpg");
    CHECK(cams[0].fy == 510.0);
    check_quarter_turn(cams[0]);
    CHECK(cams[1].name == "right.jpg");
    CHECK(cams[1].fx == 300.0);
    CHECK(cams[1].cy == 100.0);
}

TEST_CASE("read_colmap_cameras refuses distorted models naming the file, camera and model", "[colmap]") {
    const std::string t = model_dir("colmap_text_opencv");
    write_text(t + "/cameras.txt", "1 PINHOLE 10 10 5 5 5 5\n12 OPENCV 640 480 500 500 320 240 0.1 0 0 0\n");
    write_text(t + "/images.txt", "1 1 0 0 0 0 0 0 12 a.png\n\n");
    CHECK_THROWS_WITH(avsplat::read_colmap_cameras(t),
                      Catch::Contains(t + "/cameras.txt") && Catch::Contains("camera 12") &&
                          Catch::Contains("OPENCV") && Catch::Contains("line 2"));
    const std::string b = model_dir("colmap_binary_radial");
    write_bin(b, {{6, 2, 640, 480, {500, 320, 240, 0.01}}}, {{1, {1, 0, 0, 0}, {0, 0, 0}, 6, "a.png", 0}});
    CHECK_THROWS_WITH(avsplat::read_colmap_cameras(b), Catch::Contains(b + "/cameras.bin") &&
                                                           Catch::Contains("camera 6") &&
                                                           Catch::Contains("SIMPLE_RADIAL"));
}

TEST_CASE("read_colmap_cameras rejects broken models with the file and record", "[colmap]") {
    const std::string d = model_dir("colmap_broken");
    write_text(d + "/cameras.txt", "1 PINHOLE 10 10 5 5 5 5\n");
    write_text(d + "/images.txt", "1 1 0 0 0 0 0 0 2 a.png\n\n");
    CHECK_THROWS_WITH(avsplat::read_colmap_cameras(d), Catch::Contains("images.txt") && Catch::Contains("camera 2"));
    write_text(d + "/images.txt", "1 0 0 0 0 0 0 0 1 a.png\n\n");
    CHECK_THROWS_WITH(avsplat::read_colmap_cameras(d), Catch::Contains("line 1") && Catch::Contains("quaternion"));
    write_text(d + "/images.txt", "1 1 0 0 x 0 0 0 1 a.png\n\n");
    CHECK_THROWS_AS(avsplat::read_colmap_cameras(d), avsplat::IOError);
    const std::string b = model_dir("colmap_truncated");
    write_bin(b, {{1, 1, 10, 10, {5, 5, 5, 5}}}, {{1, {1, 0, 0, 0}, {0, 0, 0}, 1, "a.png", 2}});
    std::filesystem::resize_file(b + "/images.bin", std::filesystem::file_size(b + "/images.bin") - 8);
    CHECK_THROWS_WITH(avsplat::read_colmap_cameras(b), Catch::Contains("images.bin") && Catch::Contains("truncated"));
    CHECK_THROWS_WITH(avsplat::read_colmap_cameras(model_dir("colmap_none")), Catch::Contains("not a COLMAP model"));
}
