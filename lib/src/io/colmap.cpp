#include "avsplat/io/colmap.h"

#include "avsplat/core/error.h"
#include "input_file.h"

#include <Eigen/Geometry>

#include <sys/stat.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <utility>

namespace avsplat {

namespace {

struct Intrinsics {
    double fx, fy, cx, cy;
    int width, height;
};

// COLMAP's camera models by id, with their parameter counts (colmap/sensor/models.h).
struct ModelInfo {
    const char* name;
    int params;
};
constexpr ModelInfo kModels[] = {{"SIMPLE_PINHOLE", 3}, {"PINHOLE", 4},          {"SIMPLE_RADIAL", 4},
                                 {"RADIAL", 5},         {"OPENCV", 8},           {"OPENCV_FISHEYE", 8},
                                 {"FULL_OPENCV", 12},   {"FOV", 5},              {"SIMPLE_RADIAL_FISHEYE", 4},
                                 {"RADIAL_FISHEYE", 5}, {"THIN_PRISM_FISHEYE", 12}, {"RAD_TAN_THIN_PRISM_FISHEYE", 16}};
constexpr int kModelCount = int(sizeof kModels / sizeof kModels[0]);

bool exists(const std::string& p, bool dir) {
    struct stat st;
    return ::stat(p.c_str(), &st) == 0 && (dir ? S_ISDIR(st.st_mode) : S_ISREG(st.st_mode));
}

std::string dirname_of(const std::string& p) {
    const auto slash = p.find_last_of('/');
    return slash == std::string::npos ? std::string(".") : p.substr(0, slash == 0 ? 1 : slash);
}

std::string basename_of(const std::string& p) {
    const auto slash = p.find_last_of('/');
    return slash == std::string::npos ? p : p.substr(slash + 1);
}

Intrinsics pinhole(const std::string& file, const std::string& where, long long camera_id, const std::string& model,
                   const std::vector<double>& p, long long width, long long height) {
    if (model != "PINHOLE" && model != "SIMPLE_PINHOLE")
        throw IOError(file + ": " + where + ": camera " + std::to_string(camera_id) + " has model " + model +
                      ", which has lens distortion; only PINHOLE and SIMPLE_PINHOLE are read "
                      "(undistort the images first: colmap image_undistorter)");
    const std::size_t need = model == "PINHOLE" ? 4 : 3;
    if (p.size() != need)
        throw IOError(file + ": " + where + ": camera " + std::to_string(camera_id) + " (" + model + ") has " +
                      std::to_string(p.size()) + " parameters, expected " + std::to_string(need));
    if (width <= 0 || height <= 0 || width > (1 << 30) || height > (1 << 30))
        throw IOError(file + ": " + where + ": camera " + std::to_string(camera_id) + " has image size " +
                      std::to_string(width) + "x" + std::to_string(height));
    for (double v : p)
        if (!std::isfinite(v))
            throw IOError(file + ": " + where + ": camera " + std::to_string(camera_id) + " has a non-finite parameter");
    Intrinsics k;
    k.fx = p[0];
    k.fy = need == 4 ? p[1] : p[0];
    k.cx = p[need - 2];
    k.cy = p[need - 1];
    k.width = int(width);
    k.height = int(height);
    return k;
}

Camera make_camera(const std::string& file, const std::string& where, long long image_id, const double q[4],
                   const double t[3], const Intrinsics& k, const std::string& name) {
    const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
    if (!(quat.norm() > 1e-12) || !std::isfinite(quat.norm()) || !std::isfinite(t[0] + t[1] + t[2]))
        throw IOError(file + ": " + where + ": image " + std::to_string(image_id) +
                      " has a zero or non-finite rotation quaternion or translation");
    Eigen::Matrix4d w2c = Eigen::Matrix4d::Identity();
    w2c.block<3, 3>(0, 0) = quat.normalized().toRotationMatrix();
    w2c.block<3, 1>(0, 3) = Eigen::Vector3d(t[0], t[1], t[2]);
    Camera c(k.fx, k.fy, k.cx, k.cy, k.width, k.height, w2c);
    c.name = name;
    try {
        c.validate();
    } catch (const std::invalid_argument& e) {
        throw IOError(file + ": " + where + ": image " + std::to_string(image_id) + ": " + e.what());
    }
    return c;
}

// ---- text ----

std::map<long long, Intrinsics> read_cameras_txt(const std::string& path) {
    io::regular_file_size(path);
    std::ifstream in(path);
    if (!in) throw IOError(path + ": cannot open for reading");
    std::map<long long, Intrinsics> cams;
    std::string line;
    for (int lineno = 1; std::getline(in, line); ++lineno) {
        std::istringstream s(line);
        std::string first;
        if (!(s >> first) || first[0] == '#') continue;
        const std::string where = "line " + std::to_string(lineno);
        long long id = 0, w = 0, h = 0;
        std::string model;
        try {
            std::size_t used = 0;
            id = std::stoll(first, &used);
            if (used != first.size()) throw std::invalid_argument(first);
        } catch (const std::exception&) {
            throw IOError(path + ": " + where + ": expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS..., got '" + first + "'");
        }
        if (!(s >> model >> w >> h))
            throw IOError(path + ": " + where + ": expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...");
        std::vector<double> params;
        for (double v; s >> v;) params.push_back(v);
        if (!s.eof()) throw IOError(path + ": " + where + ": camera " + std::to_string(id) + ": a parameter is not a number");
        if (cams.count(id)) throw IOError(path + ": " + where + ": camera " + std::to_string(id) + " appears twice");
        cams[id] = pinhole(path, where, id, model, params, w, h);
    }
    return cams;
}

std::vector<Camera> read_images_txt(const std::string& path, const std::map<long long, Intrinsics>& cams,
                                    const std::string& cameras_path) {
    io::regular_file_size(path);
    std::ifstream in(path);
    if (!in) throw IOError(path + ": cannot open for reading");
    std::vector<Camera> out;
    std::string line;
    for (int lineno = 1; std::getline(in, line); ++lineno) {
        std::istringstream s(line);
        std::string first;
        if (!(s >> first) || first[0] == '#') continue;
        const std::string where = "line " + std::to_string(lineno);
        std::istringstream full(line);
        long long image_id = 0, camera_id = 0;
        double q[4], t[3];
        if (!(full >> image_id >> q[0] >> q[1] >> q[2] >> q[3] >> t[0] >> t[1] >> t[2] >> camera_id))
            throw IOError(path + ": " + where + ": expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
        std::string name;
        std::getline(full >> std::ws, name);
        while (!name.empty() && (name.back() == '\r' || name.back() == ' ')) name.pop_back();
        const auto it = cams.find(camera_id);
        if (it == cams.end())
            throw IOError(path + ": " + where + ": image " + std::to_string(image_id) + " names camera " +
                          std::to_string(camera_id) + ", which " + cameras_path + " does not hold");
        out.push_back(make_camera(path, where, image_id, q, t, it->second, name));
        // The next line lists the image's 2D points (possibly empty); it is not read.
        std::getline(in, line);
        ++lineno;
    }
    return out;
}

// ---- binary (little endian, as COLMAP writes) ----

class BinaryReader {
public:
    explicit BinaryReader(const std::string& path) : path_(path), size_(io::regular_file_size(path)), in_(path, std::ios::binary) {
        if (!in_) throw IOError(path + ": cannot open for reading");
    }
    template <class T>
    T get(const std::string& what) {
        T v;
        if (!in_.read(reinterpret_cast<char*>(&v), sizeof v))
            throw IOError(path_ + ": truncated: the file ends inside " + what);
        pos_ += sizeof v;
        return v;
    }
    std::string get_string(const std::string& what) {
        std::string s;
        for (char ch; (ch = get<char>(what)) != '\0';) s.push_back(ch);
        return s;
    }
    void skip(std::uint64_t bytes, const std::string& what) {
        if (bytes > size_ - pos_) throw IOError(path_ + ": truncated: the file ends inside " + what);
        in_.seekg(std::streamoff(bytes), std::ios::cur);
        pos_ += bytes;
    }
    std::uint64_t remaining() const { return size_ - pos_; }
    const std::string& path() const { return path_; }

private:
    std::string path_;
    std::uint64_t size_;
    std::uint64_t pos_ = 0;
    std::ifstream in_;
};

std::map<long long, Intrinsics> read_cameras_bin(const std::string& path) {
    BinaryReader r(path);
    const auto n = r.get<std::uint64_t>("the camera count");
    // Each record holds at least 24 bytes of header and 3 parameters: a count the file cannot
    // hold is corrupt, not a reason to allocate.
    if (n > r.remaining() / 48) throw IOError(path + ": camera count " + std::to_string(n) + " is more than the file holds");
    std::map<long long, Intrinsics> cams;
    for (std::uint64_t i = 0; i < n; ++i) {
        const std::string where = "camera record " + std::to_string(i);
        const long long id = r.get<std::uint32_t>(where);
        const int model_id = r.get<std::int32_t>(where);
        const auto w = r.get<std::uint64_t>(where);
        const auto h = r.get<std::uint64_t>(where);
        if (model_id < 0 || model_id >= kModelCount)
            throw IOError(path + ": " + where + ": camera " + std::to_string(id) + " has unknown model id " +
                          std::to_string(model_id));
        std::vector<double> params(std::size_t(kModels[model_id].params));
        for (double& p : params) p = r.get<double>(where);
        if (cams.count(id)) throw IOError(path + ": " + where + ": camera " + std::to_string(id) + " appears twice");
        cams[id] = pinhole(path, where, id, kModels[model_id].name, params, (long long)std::min<std::uint64_t>(w, 1ull << 40),
                           (long long)std::min<std::uint64_t>(h, 1ull << 40));
    }
    return cams;
}

std::vector<Camera> read_images_bin(const std::string& path, const std::map<long long, Intrinsics>& cams,
                                    const std::string& cameras_path) {
    BinaryReader r(path);
    const auto n = r.get<std::uint64_t>("the image count");
    if (n > r.remaining() / 73) throw IOError(path + ": image count " + std::to_string(n) + " is more than the file holds");
    std::vector<Camera> out;
    out.reserve(std::size_t(n));
    for (std::uint64_t i = 0; i < n; ++i) {
        const std::string where = "image record " + std::to_string(i);
        const long long image_id = r.get<std::uint32_t>(where);
        double q[4], t[3];
        for (double& v : q) v = r.get<double>(where);
        for (double& v : t) v = r.get<double>(where);
        const long long camera_id = r.get<std::uint32_t>(where);
        const std::string name = r.get_string(where);
        const auto points = r.get<std::uint64_t>(where);
        if (points > r.remaining() / 24) throw IOError(path + ": truncated: the file ends inside " + where);
        r.skip(points * 24, where);  // x, y (double) and point3D id (int64) per point
        const auto it = cams.find(camera_id);
        if (it == cams.end())
            throw IOError(path + ": " + where + ": image " + std::to_string(image_id) + " names camera " +
                          std::to_string(camera_id) + ", which " + cameras_path + " does not hold");
        out.push_back(make_camera(path, where, image_id, q, t, it->second, name));
    }
    return out;
}

// The directory and extension (".bin" or ".txt") of the model at `path`, or {"", ""}.
std::pair<std::string, std::string> locate(const std::string& path) {
    if (exists(path, true)) {
        for (const char* ext : {".bin", ".txt"})
            if (exists(path + "/cameras" + ext, false) && exists(path + "/images" + ext, false)) return {path, ext};
        return {"", ""};
    }
    const std::string base = basename_of(path);
    for (const char* ext : {".bin", ".txt"})
        if (base == std::string("cameras") + ext || base == std::string("images") + ext) return {dirname_of(path), ext};
    return {"", ""};
}

}  // namespace

bool is_colmap_model(const std::string& path) { return !locate(path).first.empty(); }

std::vector<Camera> read_colmap_cameras(const std::string& path) {
    const auto [dir, ext] = locate(path);
    if (dir.empty())
        throw IOError(path + ": not a COLMAP model (expected a directory with cameras.bin and images.bin, or "
                             "cameras.txt and images.txt, or one of those files)");
    const std::string cameras = dir + "/cameras" + ext, images = dir + "/images" + ext;
    if (ext == ".bin") return read_images_bin(images, read_cameras_bin(cameras), cameras);
    return read_images_txt(images, read_cameras_txt(cameras), cameras);
}

}  // namespace avsplat
