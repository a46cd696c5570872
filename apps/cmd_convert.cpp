// `avsplat convert IN OUT`: between the Gaussian formats (read by content, written by name:
// .ply, .compressed.ply, .splat, ...), optionally moved by a similarity transform, or to an
// Open3D point cloud format (.pcd, .xyzrgb, .pts) as a coloured preview.
#include "commands.h"
#include "prediction_npz.h"

#include "avsplat/core/error.h"
#include "avsplat/core/transform.h"
#include "avsplat/io/gaussian_io.h"
#ifdef AVSPLAT_WITH_OPEN3D
#include "avsplat/open3d/conversion.h"

#include <open3d/io/PointCloudIO.h>
#endif

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <vector>

namespace avsplat::cli {

namespace {

struct Motion {
    std::vector<double> rotate;     // 3 Euler angles (degrees), 4 quaternion values or 9 matrix entries
    std::vector<double> translate;  // 3 values
    double scale = 1.0;
    std::string axes;               // "FROM:TO", e.g. "RUB:RDF"
    bool any() const { return !rotate.empty() || !translate.empty() || scale != 1.0 || !axes.empty(); }
};

// The rotation --rotate names: Euler angles x, y, z in degrees applied about x, then y, then z
// (R = Rz Ry Rx, as splat-transform's -r), a quaternion w, x, y, z, or a row-major matrix.
Eigen::Matrix3d rotation_of(const std::vector<double>& v) {
    if (v.empty()) return Eigen::Matrix3d::Identity();
    if (v.size() == 3) {
        const double k = M_PI / 180.0;
        return (Eigen::AngleAxisd(v[2] * k, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(v[1] * k, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(v[0] * k, Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
    }
    if (v.size() == 4) {
        Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
        if (!(q.norm() > 0) || !std::isfinite(q.norm())) throw std::invalid_argument("--rotate: the quaternion must be finite and non-zero");
        return q.normalized().toRotationMatrix();
    }
    if (v.size() == 9) {
        Eigen::Matrix3d m;
        for (int i = 0; i < 9; ++i) m(i / 3, i % 3) = v[static_cast<std::size_t>(i)];
        return m;
    }
    throw std::invalid_argument("--rotate: give 3 Euler angles (degrees), 4 quaternion values w,x,y,z or 9 matrix entries, not " +
                                std::to_string(v.size()) + " values");
}

void run_convert(const std::string& in, const std::string& out, bool drop_invalid, const Motion& motion) {
    GaussianCloud cloud = read_gaussian_input(in);
    if (drop_invalid) {
        const SanitizeReport rep = sanitize(cloud);
        std::printf("sanitize: %s\n", rep.summary().c_str());
    }
    if (motion.any()) {
        // x -> scale * R * C x + t, C the change of axes.
        Eigen::Matrix3d change = Eigen::Matrix3d::Identity();
        if (!motion.axes.empty()) {
            const auto colon = motion.axes.find(':');
            if (colon == std::string::npos) throw std::invalid_argument("--axes: expected FROM:TO, e.g. RUB:RDF");
            change = coordinate_system_change(motion.axes.substr(0, colon), motion.axes.substr(colon + 1));
        }
        Eigen::Vector3d t = Eigen::Vector3d::Zero();
        if (!motion.translate.empty()) {
            if (motion.translate.size() != 3) throw std::invalid_argument("--translate: expected x,y,z");
            t = Eigen::Vector3d(motion.translate[0], motion.translate[1], motion.translate[2]);
        }
        cloud = transform(cloud, rotation_of(motion.rotate) * change, t, motion.scale);
    }
    const std::string ext = file_extension(out);
    if (ext == ".pcd" || ext == ".xyzrgb" || ext == ".pts") {
#ifdef AVSPLAT_WITH_OPEN3D
        if (!open3d::io::WritePointCloud(out, to_open3d_legacy(cloud)))
            throw IOError(out + ": Open3D could not write the point cloud");
#else
        throw IOError(out + ": point-cloud formats need avsplat built with Open3D");
#endif
    } else {
        write_gaussians(out, cloud);
    }
    std::printf("wrote %zu Gaussians to %s\n", cloud.size(), out.c_str());
}

}  // namespace

void add_convert(CLI::App& app) {
    auto* cmd = app.add_subcommand("convert", "Convert between Gaussian formats (.ply, .compressed.ply, .splat; input detected by content), optionally moved by --axes/--rotate/--scale/--translate, or export a preview point cloud (.pcd, .xyzrgb, .pts)");
    auto in = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto drop = std::make_shared<bool>(false);
    auto motion = std::make_shared<Motion>();
    cmd->add_option("input", *in, "input Gaussians (3DGS .ply, compressed .ply, .splat, detected by content; or a prediction .npz: per-pixel Gaussians or point maps)")->required()->check(CLI::ExistingPath);
    cmd->add_option("output", *out, "output file: .ply, .compressed.ply, .splat (by name), or a preview .pcd, .xyzrgb, .pts")->required();
    cmd->add_flag("--drop-invalid", *drop, "drop invalid Gaussians (counted) instead of failing");
    cmd->add_option("--axes", motion->axes, "change of axis convention FROM:TO, e.g. RUB:RDF (letters R/L, U/D, F/B), applied first");
    cmd->add_option("--rotate", motion->rotate, "rotation about the origin in the file's coordinates: Euler angles x,y,z in degrees (about x, then y, then z), a quaternion w,x,y,z, or 9 row-major matrix entries")->delimiter(',')->expected(3, 9);
    cmd->add_option("--scale", motion->scale, "uniform scale factor (> 0)");
    cmd->add_option("--translate", motion->translate, "translation x,y,z, applied last")->delimiter(',')->expected(3);
    cmd->callback([in, out, drop, motion] { run_convert(*in, *out, *drop, *motion); });
}

}  // namespace avsplat::cli
