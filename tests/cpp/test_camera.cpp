#include "avsplat/core/camera.h"
#include "avsplat/core/error.h"
#include "avsplat/io/camera_json.h"

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <cmath>
#include <fstream>

using avsplat::Camera;

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

void write_text(const std::string& path, const std::string& text) {
    std::ofstream(path) << text;
}

Eigen::Vector2d project(const Camera& c, const Eigen::Vector3d& p) {
    const Eigen::Vector4d q = c.world_to_camera * p.homogeneous();
    return {c.fx * q.x() / q.z() + c.cx, c.fy * q.y() / q.z() + c.cy};
}

}  // namespace

TEST_CASE("look_at puts the target at the principal point with OpenCV axes", "[camera]") {
    const Eigen::Vector3d eye(1, 2, 3), target(0, 0, 0), up(0, 0, 1);
    const Camera c = Camera::look_at(eye, target, up, 60.0, 640, 480);
    CHECK((c.position() - eye).norm() < 1e-12);
    const Eigen::Vector2d t = project(c, target);
    CHECK(t.x() == Approx(320.0));
    CHECK(t.y() == Approx(240.0));
    // A point above the target (world +z) appears above the centre: smaller v.
    CHECK(project(c, Eigen::Vector3d(0, 0, 0.1)).y() < 240.0);
    // fy from the field of view: half height / tan(fov / 2).
    CHECK(c.fy == Approx(240.0 / std::tan(M_PI / 6)));
    CHECK_NOTHROW(c.validate());
    CHECK((c.camera_to_world() * c.world_to_camera - Eigen::Matrix4d::Identity()).norm() < 1e-12);
    CHECK_THROWS_AS(Camera::look_at(eye, eye, up, 60, 10, 10), std::invalid_argument);
    CHECK_THROWS_AS(Camera::look_at(eye, target, eye, 60, 10, 10), std::invalid_argument);
}

TEST_CASE("validate rejects unusable cameras naming the field", "[camera]") {
    Camera c(100, 100, 50, 50, 100, 100);
    REQUIRE_NOTHROW(c.validate());
    Camera b = c; b.fx = 0;
    CHECK_THROWS_WITH(b.validate(), Catch::Contains("Camera.fx"));
    b = c; b.height = 0;
    CHECK_THROWS_WITH(b.validate(), Catch::Contains("Camera.height"));
    b = c; b.far = b.near;
    CHECK_THROWS_WITH(b.validate(), Catch::Contains("Camera.far"));
    b = c; b.world_to_camera(0, 0) = 2;
    CHECK_THROWS_WITH(b.validate(), Catch::Contains("world_to_camera"));
    b = c; b.world_to_camera(0, 3) = NAN;
    CHECK_THROWS_WITH(b.validate(), Catch::Contains("world_to_camera"));
}

TEST_CASE("avsplat camera JSON round trip is exact", "[camera][json]") {
    Camera a = Camera::look_at({0.3, -2, 1.1}, {0, 0, 0}, {0, 0, 1}, 47.3, 320, 200, 0.05, 80);
    a.name = "view_0";
    const Camera b(200, 210, 99.5, 100.25, 200, 200);
    avsplat::write_cameras_json(tmp("cams.json"), {a, b});
    const auto cams = avsplat::read_cameras_json(tmp("cams.json"));
    REQUIRE(cams.size() == 2);
    CHECK(cams[0].world_to_camera == a.world_to_camera);
    CHECK(cams[0].fx == a.fx);
    CHECK(cams[0].near == a.near);
    CHECK(cams[0].far == a.far);
    CHECK(cams[0].name == "view_0");
    CHECK(cams[1].cy == 100.25);
    CHECK(avsplat::read_camera_json(tmp("cams.json"), 1).fy == 210);
    CHECK_THROWS_AS(avsplat::read_camera_json(tmp("cams.json"), 2), avsplat::IOError);
}

TEST_CASE("3DGS cameras.json maps rotation (c2w) and position", "[camera][json]") {
    // Camera at (0, 0, -5) looking along +z: identity rotation.
    write_text(tmp("inria.json"), R"([{"id": 0, "img_name": "00000", "width": 100, "height": 80,
        "position": [0, 0, -5], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fy": 90, "fx": 91}])");
    const Camera c = avsplat::read_camera_json(tmp("inria.json"));
    CHECK(c.name == "00000");
    CHECK(c.fx == 91);
    CHECK(c.cx == 50);
    CHECK(c.cy == 40);
    CHECK((c.position() - Eigen::Vector3d(0, 0, -5)).norm() < 1e-12);
    CHECK(project(c, {0, 0, 0}).isApprox(Eigen::Vector2d(50, 40)));
}

TEST_CASE("nerfstudio transforms.json converts OpenGL axes to OpenCV", "[camera][json]") {
    // OpenGL camera at (0, 0, 5) with identity c2w looks down -z at the origin; y is up.
    write_text(tmp("transforms.json"), R"({"fl_x": 100, "fl_y": 100, "cx": 64, "cy": 48, "w": 128, "h": 96,
        "frames": [{"file_path": "images/a.png", "transform_matrix":
        [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]]},
        {"file_path": "b.png", "fl_x": 50, "transform_matrix":
        [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5], [0, 0, 0, 1]]}]})");
    const auto cams = avsplat::read_cameras_json(tmp("transforms.json"));
    REQUIRE(cams.size() == 2);
    CHECK(project(cams[0], {0, 0, 0}).isApprox(Eigen::Vector2d(64, 48)));
    // World +y is up in the image: smaller v.
    CHECK(project(cams[0], {0, 1, 0}).y() < 48);
    CHECK(project(cams[0], {1, 0, 0}).x() > 64);
    CHECK(cams[1].fx == 50);
    CHECK(cams[1].fy == 100);
    CHECK(cams[0].name == "images/a.png");
}

TEST_CASE("bad camera files raise IOError naming the file and the field", "[camera][json]") {
    CHECK_THROWS_WITH(avsplat::read_cameras_json(tmp("missing.json")), Catch::Contains("missing.json"));
    write_text(tmp("bad.json"), "{ not json");
    CHECK_THROWS_WITH(avsplat::read_cameras_json(tmp("bad.json")), Catch::Contains("not valid JSON"));
    write_text(tmp("nofx.json"), R"([{"fy": 1, "cx": 0, "cy": 0, "width": 2, "height": 2,
        "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}])");
    CHECK_THROWS_WITH(avsplat::read_cameras_json(tmp("nofx.json")), Catch::Contains("\"fx\""));
    write_text(tmp("badmat.json"), R"([{"fx": 1, "fy": 1, "cx": 0, "cy": 0, "width": 2, "height": 2,
        "world_to_camera": [[1,0,0],[0,1,0],[0,0,1]]}])");
    CHECK_THROWS_WITH(avsplat::read_cameras_json(tmp("badmat.json")), Catch::Contains("4 x 4"));
    write_text(tmp("negf.json"), R"([{"fx": -1, "fy": 1, "cx": 0, "cy": 0, "width": 2, "height": 2,
        "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}])");
    CHECK_THROWS_WITH(avsplat::read_cameras_json(tmp("negf.json")), Catch::Contains("camera 0: Camera.fx"));
}

TEST_CASE("deeply nested camera JSON is refused, not a stack overflow", "[camera][json][hostile]") {
    // 100,000 nested objects (1 MB) used to overflow the stack in the JSON destructor.
    const int depth = 100000;
    for (const char* kind : {"object", "array"}) {
        const std::string path = tmp(std::string("nested_") + kind + ".json");
        {
            std::ofstream f(path);
            for (int i = 0; i < depth; ++i) f << (kind[0] == 'o' ? "{\"a\":" : "[");
            f << "1";
            for (int i = 0; i < depth; ++i) f << (kind[0] == 'o' ? "}" : "]");
        }
        try {
            avsplat::read_cameras_json(path);
            FAIL("a nested file was accepted");
        } catch (const avsplat::IOError& e) {
            const std::string msg = e.what();
            CHECK(msg.find(path) != std::string::npos);
            CHECK(msg.find("nested deeper than 64") != std::string::npos);
        }
    }
    // A legitimate file with its five levels still reads.
    const std::string ok = tmp("nested_ok.json");
    {
        std::ofstream f(ok);
        f << R"({"fl_x": 100, "fl_y": 100, "cx": 32, "cy": 24, "w": 64, "h": 48,
                 "frames": [{"file_path": "a.png", "transform_matrix":
                   [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]})";
    }
    CHECK(avsplat::read_cameras_json(ok).size() == 1);
}

TEST_CASE("camera image sizes must be whole numbers that fit int", "[camera][json][hostile]") {
    // Found by fuzzing: "height": 8888888848 was cast to int (undefined behaviour), and a width of
    // 64.5 silently became 64.
    const std::string eye = R"("world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]])";
    const std::pair<std::string, std::string> cases[] = {
        {R"([{"fx": 100, "fy": 100, "cx": 32, "cy": 24, "width": 64, "height": 8888888848, )" + eye + "}]", "\"height\""},
        {R"([{"fx": 100, "fy": 100, "cx": 32, "cy": 24, "width": 64.5, "height": 48, )" + eye + "}]", "\"width\""},
        {R"({"fl_x": 100, "fl_y": 100, "cx": 32, "cy": 24, "w": 1e300, "h": 48, "frames": [{"transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})", "\"w\""},
        {R"([{"img_name": "a", "width": -3, "height": 48, "position": [0,0,0], "rotation": [[1,0,0],[0,1,0],[0,0,1]], "fx": 100, "fy": 100}])", "\"width\""},
    };
    for (std::size_t k = 0; k < std::size(cases); ++k) {
        const std::string path = tmp("bad_size_" + std::to_string(k) + ".json");
        std::ofstream(path) << cases[k].first;
        CHECK_THROWS_WITH(avsplat::read_cameras_json(path),
                          Catch::StartsWith(path) && Catch::Contains(cases[k].second) &&
                              Catch::Contains("whole number of pixels"));
    }
}
