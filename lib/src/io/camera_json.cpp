#include "avsplat/io/camera_json.h"
#include "avsplat/io/atomic_file.h"

#include "avsplat/core/error.h"
#include "io/input_file.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <stdexcept>

namespace avsplat {

namespace {

/// Deepest nesting a camera file may have (ours and transforms.json need five levels).
constexpr int kMaxJsonDepth = 64;

using nlohmann::json;

[[noreturn]] void fail(const std::string& path, const std::string& what) {
    throw IOError(path + ": " + what);
}

double number(const json& j, const char* key, const std::string& where, const std::string& path) {
    auto it = j.find(key);
    if (it == j.end() || !it->is_number()) fail(path, where + ": missing or non-numeric \"" + key + "\"");
    return it->get<double>();
}

// An image size: a whole number that fits int. A cast of 64.5 or 8888888848 would silently give
// 64 or an undefined value.
int pixels(const json& v, const char* key, const std::string& where, const std::string& path) {
    const double d = v.get<double>();
    if (!(d >= 0.0 && d <= 2147483647.0) || d != std::floor(d))
        fail(path, where + ": \"" + key + "\" must be a whole number of pixels that fits int, got " + v.dump());
    return static_cast<int>(d);
}

int pixels_at(const json& j, const char* key, const std::string& where, const std::string& path) {
    auto it = j.find(key);
    if (it == j.end() || !it->is_number()) fail(path, where + ": missing or non-numeric \"" + key + "\"");
    return pixels(*it, key, where, path);
}

double number_or(const json& j, const char* key, double fallback) {
    auto it = j.find(key);
    return (it != j.end() && it->is_number()) ? it->get<double>() : fallback;
}

template <int R, int C>
Eigen::Matrix<double, R, C> matrix(const json& j, const char* key, const std::string& where,
                                   const std::string& path) {
    auto it = j.find(key);
    const std::string what = where + ": \"" + key + "\" must be a " + std::to_string(R) + " x " +
                             std::to_string(C) + " array of numbers";
    if (it == j.end() || !it->is_array()) fail(path, what);
    Eigen::Matrix<double, R, C> m;
    const json& a = *it;
    if (R == 1 || C == 1) {  // a flat vector
        if (a.size() != static_cast<std::size_t>(R * C)) fail(path, what);
        for (int k = 0; k < R * C; ++k) {
            if (!a[k].is_number()) fail(path, what);
            m(k) = a[k].get<double>();
        }
        return m;
    }
    if (a.size() != static_cast<std::size_t>(R)) fail(path, what);
    for (int r = 0; r < R; ++r) {
        if (!a[r].is_array() || a[r].size() != static_cast<std::size_t>(C)) fail(path, what);
        for (int c = 0; c < C; ++c) {
            if (!a[r][c].is_number()) fail(path, what);
            m(r, c) = a[r][c].get<double>();
        }
    }
    return m;
}

Camera from_avsplat(const json& j, const std::string& where, const std::string& path) {
    Camera cam(number(j, "fx", where, path), number(j, "fy", where, path),
               number(j, "cx", where, path), number(j, "cy", where, path),
               pixels_at(j, "width", where, path), pixels_at(j, "height", where, path),
               matrix<4, 4>(j, "world_to_camera", where, path), number_or(j, "near", 0.01),
               number_or(j, "far", 1e10));
    if (j.contains("name") && j["name"].is_string()) cam.name = j["name"].get<std::string>();
    return cam;
}

// INRIA 3DGS cameras.json: rotation is camera-to-world, position the camera centre.
Camera from_inria(const json& j, const std::string& where, const std::string& path) {
    const Eigen::Matrix3d R = matrix<3, 3>(j, "rotation", where, path);
    const Eigen::Vector3d t = matrix<3, 1>(j, "position", where, path);
    Eigen::Matrix4d w2c = Eigen::Matrix4d::Identity();
    w2c.block<3, 3>(0, 0) = R.transpose();
    w2c.block<3, 1>(0, 3) = -R.transpose() * t;
    const int w = pixels_at(j, "width", where, path);
    const int h = pixels_at(j, "height", where, path);
    Camera cam(number(j, "fx", where, path), number(j, "fy", where, path), 0.5 * w, 0.5 * h, w,
               h, w2c);
    if (j.contains("img_name") && j["img_name"].is_string())
        cam.name = j["img_name"].get<std::string>();
    return cam;
}

// nerfstudio / instant-ngp transforms.json: camera-to-world with OpenGL axes.
std::vector<Camera> from_transforms(const json& root, const std::string& path) {
    std::vector<Camera> out;
    const json& frames = root["frames"];
    if (!frames.is_array()) fail(path, "\"frames\" must be an array");
    for (std::size_t k = 0; k < frames.size(); ++k) {
        const json& f = frames[k];
        const std::string where = "frames[" + std::to_string(k) + "]";
        auto pick = [&](const char* key) -> const json* {
            if (f.contains(key) && f[key].is_number()) return &f[key];
            if (root.contains(key) && root[key].is_number()) return &root[key];
            return nullptr;
        };
        const json* jw = pick("w");
        const json* jh = pick("h");
        if (!jw || !jh) fail(path, where + ": missing \"w\" or \"h\"");
        const int w = pixels(*jw, "w", where, path), h = pixels(*jh, "h", where, path);
        double fx, fy;
        if (const json* jfx = pick("fl_x")) {
            fx = jfx->get<double>();
        } else if (const json* ang = pick("camera_angle_x")) {
            fx = 0.5 * w / std::tan(0.5 * ang->get<double>());
        } else {
            fail(path, where + ": missing \"fl_x\" or \"camera_angle_x\"");
        }
        if (const json* jfy = pick("fl_y")) {
            fy = jfy->get<double>();
        } else if (const json* ang = pick("camera_angle_y")) {
            fy = 0.5 * h / std::tan(0.5 * ang->get<double>());
        } else {
            fy = fx;
        }
        const json* jcx = pick("cx");
        const json* jcy = pick("cy");
        Eigen::Matrix4d c2w = matrix<4, 4>(f, "transform_matrix", where, path);
        c2w.col(1) *= -1.0;  // OpenGL (y up, z back) -> OpenCV (y down, z forward)
        c2w.col(2) *= -1.0;
        Eigen::Matrix4d w2c = Eigen::Matrix4d::Identity();
        const Eigen::Matrix3d R = c2w.block<3, 3>(0, 0);
        w2c.block<3, 3>(0, 0) = R.transpose();
        w2c.block<3, 1>(0, 3) = -R.transpose() * c2w.block<3, 1>(0, 3);
        Camera cam(fx, fy, jcx ? jcx->get<double>() : 0.5 * w, jcy ? jcy->get<double>() : 0.5 * h,
                   w, h, w2c);
        if (f.contains("file_path") && f["file_path"].is_string())
            cam.name = f["file_path"].get<std::string>();
        out.push_back(cam);
    }
    return out;
}

json to_json(const Camera& c) {
    json m = json::array();
    for (int r = 0; r < 4; ++r)
        m.push_back({c.world_to_camera(r, 0), c.world_to_camera(r, 1), c.world_to_camera(r, 2),
                     c.world_to_camera(r, 3)});
    json j = {{"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx}, {"cy", c.cy}, {"width", c.width},
              {"height", c.height}, {"world_to_camera", m}, {"near", c.near}, {"far", c.far}};
    if (!c.name.empty()) j["name"] = c.name;
    return j;
}

}  // namespace

std::vector<Camera> read_cameras_json(const std::string& path) {
    io::regular_file_size(path);
    std::ifstream in(path);
    if (!in) fail(path, "cannot open for reading");
    json root;
    try {
        // A camera file nests a few levels; a hostile one can nest 10^5 objects, and
        // json's recursive destructor would overflow the stack on it. Refuse deep files while
        // parsing, before such a tree exists.
        root = json::parse(in, [&path](int depth, json::parse_event_t, json&) {
            if (depth > kMaxJsonDepth)
                fail(path, "JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
            return true;
        });
    } catch (const json::exception& e) {
        fail(path, std::string("not valid JSON: ") + e.what());
    }
    std::vector<Camera> cams;
    if (root.is_object() && root.contains("frames")) {
        cams = from_transforms(root, path);
    } else {
        const json* list = &root;
        json single;
        if (root.is_object() && root.contains("cameras")) {
            list = &root["cameras"];
        } else if (root.is_object()) {
            single = json::array({root});
            list = &single;
        }
        if (!list->is_array()) fail(path, "expected a camera object or a list of cameras");
        for (std::size_t k = 0; k < list->size(); ++k) {
            const json& j = (*list)[k];
            const std::string where = "camera " + std::to_string(k);
            if (!j.is_object()) fail(path, where + ": not an object");
            cams.push_back(j.contains("rotation") && j.contains("position")
                               ? from_inria(j, where, path)
                               : from_avsplat(j, where, path));
        }
    }
    for (std::size_t k = 0; k < cams.size(); ++k) {
        try {
            cams[k].validate();
        } catch (const std::invalid_argument& e) {
            fail(path, "camera " + std::to_string(k) + ": " + e.what());
        }
    }
    return cams;
}

Camera read_camera_json(const std::string& path, std::size_t index) {
    std::vector<Camera> cams = read_cameras_json(path);
    if (index >= cams.size())
        fail(path, "camera index " + std::to_string(index) + " out of range (" +
                       std::to_string(cams.size()) + " cameras)");
    return cams[index];
}

void write_cameras_json(const std::string& path, const std::vector<Camera>& cameras) {
    json list = json::array();
    for (const auto& c : cameras) list.push_back(to_json(c));
    write_file_atomically(path, list.dump(2) + "\n");
}

void write_camera_json(const std::string& path, const Camera& camera) {
    write_cameras_json(path, {camera});
}

}  // namespace avsplat
