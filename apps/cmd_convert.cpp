// `avsplat convert IN OUT`: between the Gaussian formats (.ply, .splat), or to an Open3D point
// cloud format (.pcd, .xyzrgb, .pts) as a coloured preview.
#include "commands.h"
#include "prediction_npz.h"

#include "avsplat/core/error.h"
#include "avsplat/io/gaussian_io.h"
#ifdef AVSPLAT_WITH_OPEN3D
#include "avsplat/open3d/conversion.h"
#include "open3d_log.h"

#include <open3d/io/PointCloudIO.h>
#endif

#include <cstdio>
#include <memory>

namespace avsplat::cli {

namespace {

void run_convert(const std::string& in, const std::string& out, bool drop_invalid) {
    GaussianCloud cloud = read_gaussian_input(in);
    if (drop_invalid) {
        const SanitizeReport rep = sanitize(cloud);
        std::printf("sanitize: %s\n", rep.summary().c_str());
    }
    const std::string ext = file_extension(out);
    if (ext == ".pcd" || ext == ".xyzrgb" || ext == ".pts") {
#ifdef AVSPLAT_WITH_OPEN3D
        Open3DLog log;
        if (!open3d::io::WritePointCloud(out, to_open3d_legacy(cloud)))
            throw IOError(out + ": Open3D could not write the point cloud" + log.reason());
        log.flush_to_stderr();
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
    auto* cmd = app.add_subcommand("convert", "Convert between .ply (3DGS) and .splat, or export a preview point cloud (.pcd, .xyzrgb, .pts)");
    auto in = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto drop = std::make_shared<bool>(false);
    cmd->add_option("input", *in, "input Gaussians (.ply, .splat, or a prediction .npz: per-pixel Gaussians or point maps)")->required()->check(CLI::ExistingFile);
    cmd->add_option("output", *out, "output file (.ply, .splat, .pcd, .xyzrgb, .pts)")->required();
    cmd->add_flag("--drop-invalid", *drop, "drop invalid Gaussians (counted) instead of failing");
    cmd->callback([in, out, drop] { run_convert(*in, *out, *drop); });
}

}  // namespace avsplat::cli
