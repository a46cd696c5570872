// `avsplat convert IN OUT`: between the Gaussian formats (.ply, .splat), or to an Open3D point
// cloud format (.pcd, .xyzrgb, .pts) as a coloured preview.
#include "commands.h"
#include "prediction_npz.h"

#include "avsplat/core/error.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/reduce/reduce_sh.h"
#ifdef AVSPLAT_WITH_OPEN3D
#include "avsplat/open3d/conversion.h"

#include <open3d/io/PointCloudIO.h>
#endif

#include <cstdio>
#include <memory>
#include <utility>

namespace avsplat::cli {

namespace {

void run_convert(const std::string& in, const std::string& out, bool drop_invalid, int sh_degree,
                 double sh_max_error) {
    GaussianCloud cloud = read_gaussian_input(in);
    if (drop_invalid) {
        const SanitizeReport rep = sanitize(cloud);
        std::printf("sanitize: %s\n", rep.summary().c_str());
    }
    // --sh-max-error: the smallest degree within that colour bound (reduce/reduce_sh.h);
    // --sh-degree caps the degree (a cloud already at or below it is kept as it is); both: the lower.
    if (sh_degree >= 0 || sh_max_error >= 0.0) {
        const double bound = sh_max_error >= 0.0 ? sh_max_error : 1.0 / 255.0;
        int degree = sh_max_error >= 0.0 ? reduce_sh(cloud, bound).sh_degree : cloud.sh_degree;
        if (sh_degree >= 0 && sh_degree < degree) degree = sh_degree;
        ReduceShResult rep = reduce_sh(cloud, bound, degree);
        std::printf("reduce_sh: %s\n", rep.summary().c_str());
        cloud = std::move(rep.cloud);
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
    auto* cmd = app.add_subcommand("convert", "Convert between .ply (3DGS) and .splat, or export a preview point cloud (.pcd, .xyzrgb, .pts)");
    auto in = std::make_shared<std::string>();
    auto out = std::make_shared<std::string>();
    auto drop = std::make_shared<bool>(false);
    cmd->add_option("input", *in, "input Gaussians (.ply, .splat, or a prediction .npz: per-pixel Gaussians or point maps)")->required()->check(CLI::ExistingFile);
    cmd->add_option("output", *out, "output file (.ply, .splat, .pcd, .xyzrgb, .pts)")->required();
    cmd->add_flag("--drop-invalid", *drop, "drop invalid Gaussians (counted) instead of failing");
    auto sh_degree = std::make_shared<int>(-1);
    auto sh_max_error = std::make_shared<double>(-1.0);
    cmd->add_option("--sh-degree", *sh_degree,
                    "keep SH bands up to this degree (0..3); prints the colour bound of what was dropped")
        ->check(CLI::Range(0, 3));
    cmd->add_option("--sh-max-error", *sh_max_error,
                    "keep the fewest SH bands whose dropped part changes no colour by more than this (e.g. "
                    "0.0039 = 1/255); with --sh-degree, the lower degree")
        ->check(CLI::NonNegativeNumber);
    cmd->callback([in, out, drop, sh_degree, sh_max_error] {
        run_convert(*in, *out, *drop, *sh_degree, *sh_max_error);
    });
}

}  // namespace avsplat::cli
