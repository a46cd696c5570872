// `avsplat info FILE`: what a Gaussian file holds, and what in it is invalid.
#include "commands.h"
#include "input_checks.h"
#include "input_formats.h"

#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/lod_set.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>

namespace avsplat::cli {

namespace {

struct Range {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    std::size_t non_finite = 0;
    void add(float v) {
        if (!std::isfinite(v)) { ++non_finite; return; }
        lo = std::min(lo, double(v));
        hi = std::max(hi, double(v));
    }
};

void print_range(const char* name, const float* v, std::size_t count, std::size_t stride = 1,
                 std::size_t offset = 0) {
    Range r;
    for (std::size_t k = offset; k < count; k += stride) r.add(v[k]);
    if (r.lo > r.hi) std::printf("  %-14s (no finite values)", name);
    else std::printf("  %-14s [%.6g, %.6g]", name, r.lo, r.hi);
    if (r.non_finite) std::printf("  non-finite: %zu", r.non_finite);
    std::printf("\n");
}

void run_info(const std::string& path) {
    const GaussianFormatInfo format = detect_gaussian_format(path);
    GaussianCloud cloud = read_gaussians(path);
    std::printf("%s\n  format         %s%s%s\n", path.c_str(), format.name.c_str(), format.version.empty() ? "" : ", version ",
                format.version.c_str());
    if (format.format == GaussianFormat::LodSet) {
        // The levels and their counts from lod-meta.json; the ranges below are level 0's.
        const LodSetInfo lod = read_lod_set_info(path);
        std::printf("  levels         %d (%zu leaves, depth %d, %zu SOG chunks)\n", lod.levels, lod.leaves, lod.depth,
                    lod.filenames.size());
        for (int l = 0; l < lod.levels; ++l) std::printf("    level %-4d   %zu Gaussians\n", l, lod.counts[l]);
    }
    std::printf("  gaussians      %zu\n  sh degree      %d (%d coefficients per channel)\n",
                cloud.size(), cloud.sh_degree, cloud.sh_coeffs());
    std::printf("  confidence     %s\n", cloud.has_confidence() ? "yes" : "no");
    std::printf("  extra channels %zu", cloud.extras.size());
    for (const auto& e : cloud.extras) std::printf(" %s", e.name.c_str());
    std::printf("\n");
    if (cloud.empty()) return;
    const std::size_t n = cloud.size();
    const char* axis[] = {"mean x", "mean y", "mean z"};
    for (int a = 0; a < 3; ++a) print_range(axis[a], cloud.means.data(), 3 * n, 3, a);
    print_range("scale", cloud.scales.data(), 3 * n);
    print_range("opacity", cloud.opacities.data(), n);
    print_range("sh dc", cloud.sh.data(), cloud.sh.size(), cloud.sh_coeffs() * 3);
    if (cloud.has_confidence()) print_range("confidence", cloud.confidence.data(), n);
    for (const auto& e : cloud.extras) print_range(e.name.c_str(), e.values.data(), n);
    const SanitizeReport rep = sanitize(cloud);
    std::printf("  invalid        %zu (%s)\n", rep.dropped, rep.summary().c_str());
}

}  // namespace

void add_info(CLI::App& app) {
    auto* cmd = app.add_subcommand("info", "Format and version, counts, SH degree, bounds, value ranges and invalid entries of a Gaussian file");
    auto path = std::make_shared<std::string>();
    cmd->add_option("file", *path, "Gaussian file: " + readable_formats(false))->required()->check(existing_input(true));
    cmd->callback([path] { run_info(*path); });
}

}  // namespace avsplat::cli
