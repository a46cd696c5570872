// `avsplat convert IN OUT`: between the Gaussian formats (read by content, written by name:
// .ply, .compressed.ply, .splat, ...), optionally moved by a similarity transform, to an
// Open3D point cloud format (.pcd, .xyzrgb, .pts) as a coloured preview, or to a self-contained
// .html page that shows the scene in a browser (view/web_viewer.h).
#include "commands.h"
#include "progress.h"
#include "input_checks.h"
#include "input_formats.h"
#include "viewer_camera.h"
#include "avsplat/predictions/prediction_npz.h"

#include "avsplat/core/error.h"
#include "avsplat/core/transform.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/view/web_viewer.h"
#include "avsplat/io/spz.h"
#include "avsplat/io/lod_set.h"
#ifdef AVSPLAT_WITH_OPEN3D
#include "avsplat/open3d/conversion.h"
#include "avsplat/reduce/reduce_sh.h"
#include "open3d_log.h"

#include <open3d/io/PointCloudIO.h>
#endif

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

namespace avsplat::cli {

namespace {

// What convert does to the cloud besides changing its format.
struct ConvertArgs {
    std::vector<double> rotate;     // 3 Euler angles (degrees), 4 quaternion values or 9 matrix entries
    std::vector<double> translate;  // 3 values
    double scale = 1.0;
    std::string axes;               // "FROM:TO", e.g. "RUB:RDF"
    int sh_degree = -1;             // --sh-degree (-1: keep)
    double sh_max_error = -1.0;     // --sh-max-error (-1: none)
    CameraArgs cameras;             // the initial camera of an .html page
    int spz_version = 0;            // --spz-version (0: the writer's default)
    std::vector<int> lod_levels;    // --lod-levels: levels of a LOD set, concatenated (empty: level 0)
    bool moves() const { return !rotate.empty() || !translate.empty() || scale != 1.0 || !axes.empty(); }
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

void run_convert(const std::string& in, const std::string& out, bool drop_invalid, const ConvertArgs& args) {
    const std::string ext = file_extension(out);
    if (ext != ".html" && has_cameras(args.cameras))
        throw CLI::ValidationError("cameras", "the camera options set the initial view of an .html output only");
    if (ext == ".html" && !args.cameras.file.empty()) read_camera_file(args.cameras.file);  // fail before the work
    const std::string viewer = ext == ".html" ? find_web_viewer() : std::string();
    if (args.spz_version != 0 && (ext == ".pcd" || ext == ".xyzrgb" || ext == ".pts" || ext == ".html" ||
                                  gaussian_format_for_name(out) != GaussianFormat::Spz))
        throw std::invalid_argument("--spz-version: applies to .spz output only, not '" + out + "'");
    GaussianCloud cloud;
    if (!args.lod_levels.empty()) {
        if (detect_gaussian_format(in).format != GaussianFormat::LodSet)
            throw std::invalid_argument("--lod-levels: " + in + " is not a LOD set (lod-meta.json)");
        cloud = concatenate(read_lod_set(in, args.lod_levels));
    } else {
        cloud = read_gaussian_input(in);
    }
    if (drop_invalid) {
        const SanitizeReport rep = sanitize(cloud);
        std::printf("sanitize: %s\n", rep.summary().c_str());
    }
    // --sh-max-error: the smallest degree within that colour bound (reduce/reduce_sh.h);
    // --sh-degree caps the degree (a cloud already at or below it is kept as it is); both: the lower.
    if (args.sh_degree >= 0 || args.sh_max_error >= 0.0) {
        const double bound = args.sh_max_error >= 0.0 ? args.sh_max_error : 1.0 / 255.0;
        int degree = args.sh_max_error >= 0.0 ? reduce_sh(cloud, bound).sh_degree : cloud.sh_degree;
        if (args.sh_degree >= 0 && args.sh_degree < degree) degree = args.sh_degree;
        ReduceShResult rep = reduce_sh(cloud, bound, degree);
        std::printf("reduce_sh: %s\n", rep.summary().c_str());
        cloud = std::move(rep.cloud);
    }
    if (args.moves()) {
        // x -> scale * R * C x + t, C the change of axes.
        Eigen::Matrix3d change = Eigen::Matrix3d::Identity();
        if (!args.axes.empty()) {
            const auto colon = args.axes.find(':');
            if (colon == std::string::npos) throw std::invalid_argument("--axes: expected FROM:TO, e.g. RUB:RDF");
            change = coordinate_system_change(args.axes.substr(0, colon), args.axes.substr(colon + 1));
        }
        Eigen::Vector3d t = Eigen::Vector3d::Zero();
        if (!args.translate.empty()) {
            if (args.translate.size() != 3) throw std::invalid_argument("--translate: expected x,y,z");
            t = Eigen::Vector3d(args.translate[0], args.translate[1], args.translate[2]);
        }
        cloud = transform(cloud, rotation_of(args.rotate) * change, t, args.scale);
    }
    if (ext == ".html") {
        auto [camera, options] = resolve_viewer_camera(args.cameras, cloud);
        options.title = in + " - avsplat viewer";
        write_html(out, cloud, camera, viewer, options);
    } else if (ext == ".pcd" || ext == ".xyzrgb" || ext == ".pts") {
#ifdef AVSPLAT_WITH_OPEN3D
        Open3DLog log;
        if (!open3d::io::WritePointCloud(out, to_open3d_legacy(cloud)))
            throw IOError(out + ": Open3D could not write the point cloud" + log.reason());
        log.flush_to_stderr();
#else
        throw IOError(out + ": point-cloud formats need avsplat built with Open3D");
#endif
    } else if (args.spz_version != 0) {
        SpzWriteOptions o;
        o.version = args.spz_version;
        write_spz(out, cloud, o);
    } else {
        Progress progress("writing " + out, 1);  // chunks, for the writers that report them
        const auto following = progress.follow();
        write_gaussians(out, cloud);
    }
    std::printf("wrote %zu Gaussians to %s\n", cloud.size(), out.c_str());
}

}  // namespace

void add_convert(CLI::App& app) {
    auto* cmd = app.add_subcommand("convert", "Convert between Gaussian formats (.ply, .compressed.ply, .splat, .spz, .sog, .glb; .ksplat read; input detected by content), optionally moved by --axes/--rotate/--scale/--translate, export a preview point cloud (.pcd, .xyzrgb, .pts), or a self-contained .html viewer page");
    auto in = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto drop = std::make_shared<bool>(false);
    auto args = std::make_shared<ConvertArgs>();
    cmd->add_option("input", *in, "input Gaussians: " + readable_formats(true))->required()->check(existing_input(true));
    cmd->add_option("output", *out, "output file: .ply, .compressed.ply, .splat, .spz, .sog, .glb (by name), a preview .pcd, .xyzrgb, .pts, or .html (the scene in the web viewer, one file that opens offline)")->required();
    cmd->add_option("--lod-levels", args->lod_levels,
                    "with a LOD set (lod-meta.json) as input: the levels to read, concatenated (negative from the "
                    "end, -1 the coarsest; default level 0), as splat-transform's -L")
        ->delimiter(',');
    cmd->add_flag("--drop-invalid", *drop, "drop invalid Gaussians (counted) instead of failing");
    cmd->add_option("--axes", args->axes, "change of axis convention FROM:TO, e.g. RUB:RDF (letters R/L, U/D, F/B), applied first");
    cmd->add_option("--rotate", args->rotate, "rotation about the origin in the file's coordinates: Euler angles x,y,z in degrees (about x, then y, then z), a quaternion w,x,y,z, or 9 row-major matrix entries")->delimiter(',')->expected(3, 9);
    cmd->add_option("--scale", args->scale, "uniform scale factor (> 0)");
    cmd->add_option("--translate", args->translate, "translation x,y,z, applied last")->delimiter(',')->expected(3);
    cmd->add_option("--sh-degree", args->sh_degree,
                    "keep SH bands up to this degree (0..3); prints the colour bound of what was dropped")
        ->check(CLI::Range(0, 3));
    cmd->add_option("--sh-max-error", args->sh_max_error,
                    "keep the fewest SH bands whose dropped part changes no colour by more than this (e.g. "
                    "0.0039 = 1/255); with --sh-degree, the lower degree")
        ->check(CLI::NonNegativeNumber);
    add_viewer_camera_options(*cmd, args->cameras, "Initial camera of an .html output (none given: the default framing)");
    cmd->add_option("--spz-version", args->spz_version,
                    "SPZ version to write: 4 (default), 3 for readers that predate 4, 2 for readers that predate 3 "
                    "(8-bit x, y, z rotations)")
        ->check(CLI::IsMember({2, 3, 4}));
    cmd->callback([in, out, drop, args] { run_convert(*in, *out, *drop, *args); });
}

}  // namespace avsplat::cli
