// `avsplat simplify IN OUT --target-count N | --ratio R | --max-error E [--cameras C | --orbit N | --eye ...]
//  [--method merge|voxel]`: reduces a scene to a budget of Gaussians (reduce/simplify.h). Reads
// and writes any Gaussian format (read_gaussians / write_gaussians: the format of OUT follows its
// name).
#include "camera_options.h"
#include "choice_option.h"
#include "commands.h"
#include "input_checks.h"
#include "progress.h"
#include "input_formats.h"

#include "avsplat/core/names.h"
#include "avsplat/reduce/names.h"
#include "avsplat/io/camera_json.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/reduce/simplify.h"


#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

namespace avsplat::cli {

namespace {

struct SimplifyArgs {
    std::string in, out;
    CameraArgs cameras;
    std::size_t target_count = 0;
    double ratio = 0.0, max_error = 0.0;
    SimplifyMethod method = SimplifyOptions{}.method;
    CLI::Option *target_opt = nullptr, *ratio_opt = nullptr, *error_opt = nullptr;
};

void run_simplify(const SimplifyArgs& a) {
    SimplifyOptions o;
    o.method = a.method;
    if (*a.target_opt) o.target_count = a.target_count;
    if (*a.ratio_opt) o.ratio = a.ratio;
    if (*a.error_opt) o.max_error = a.max_error;
    std::vector<Camera> cameras;
    if (!a.cameras.file.empty()) cameras = read_camera_file(a.cameras.file);
    const GaussianCloud cloud = read_gaussians(a.in);
    if (a.cameras.file.empty() && has_cameras(a.cameras)) cameras = resolve_cameras(a.cameras, cloud);
    const auto t0 = std::chrono::steady_clock::now();
    // A bar on a terminal only: in a log or a pipe the summary line says what was done.
    Progress progress(o.max_error ? "simplify: searching the count" : "simplify: Gaussians removed", 1);
    SimplifyResult r;
    {
        const auto following = progress.follow();
        r = simplify(cloud, o, cameras);
    }
    progress.finish();
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    write_gaussians(a.out, r.cloud);
    std::printf("simplify (%s): %zu -> %zu Gaussians in %.3f s", to_string(r.method).c_str(), r.input_count,
                r.output_count, seconds);
    if (std::isfinite(r.voxel_size)) std::printf(", voxel %.6g", r.voxel_size);
    if (std::isfinite(r.error)) std::printf(", rendered RMSE %.6g at %zu cameras", r.error, cameras.size());
    std::printf("\nwrote %s\n", a.out.c_str());
}

}  // namespace

void add_simplify(CLI::App& app) {
    auto* cmd = app.add_subcommand("simplify", "Reduce Gaussians to a budget (a count, a ratio or a rendered error)");
    auto a = std::make_shared<SimplifyArgs>();
    cmd->add_option("input", a->in, "input Gaussians: " + readable_formats(false))
        ->required()
        ->check(existing_input());
    cmd->add_option("output", a->out, "output file; its name picks the format (.ply, .splat, ...)")->required();
    a->target_opt = cmd->add_option("--target-count", a->target_count, "Gaussians to keep (>= 1)")
                        ->check(at_least_one());
    // "25%" reads as 0.25: a percentage is how a budget is often said.
    const CLI::Validator percent(
        [](std::string& word) {
            if (word.empty() || word.back() != '%') return std::string();
            try {
                std::size_t used = 0;
                const double v = std::stod(word.substr(0, word.size() - 1), &used);
                if (used + 1 != word.size()) throw std::invalid_argument(word);
                char buf[64];
                std::snprintf(buf, sizeof buf, "%.17g", v / 100.0);
                word = buf;
                return std::string();
            } catch (const std::exception&) {
                return "'" + word + "' is not a percentage";
            }
        },
        "", "PERCENT");
    a->ratio_opt = cmd->add_option("--ratio", a->ratio,
                                   "keep this fraction of the Gaussians, in (0, 1], or a percentage (25%)")
                       ->transform(percent)
                       ->check(CLI::Range(0.0, 1.0));
    a->error_opt = cmd->add_option("--max-error", a->max_error,
                                   "the fewest Gaussians whose renders at the cameras (--cameras, --orbit or --eye) "
                                   "stay within this RMSE (RGB in [0, 1])")
                       ->check(CLI::Validator(
                           [](std::string& t) -> std::string {
                               std::size_t used = 0;
                               double v = 0;
                               try {
                                   v = std::stod(t, &used);
                               } catch (const std::exception&) {
                                   used = 0;
                               }
                               return used == t.size() && v > 0 && std::isfinite(v)
                                          ? std::string()
                                          : "expected a finite number > 0, got '" + t + "'";
                           },
                           "NUMBER > 0"));
    a->target_opt->excludes(a->ratio_opt)->excludes(a->error_opt);
    a->ratio_opt->excludes(a->error_opt);
    add_camera_options(*cmd, a->cameras);
    add_choice(*cmd, "--method", a->method, enum_names<SimplifyMethod>(),
               "merge: pairwise moment-matching merges; voxel: occupancy fusion at a searched voxel size");
    cmd->callback([a] {
        if (!*a->target_opt && !*a->ratio_opt && !*a->error_opt)
            throw CLI::RequiredError("one of --target-count, --ratio, --max-error");
        if (*a->error_opt && !has_cameras(a->cameras)) throw CLI::RequiredError("--cameras, --orbit or --eye (with --max-error)");
        if (*a->ratio_opt && !(a->ratio > 0.0)) throw CLI::ValidationError("--ratio", "must be > 0");
        run_simplify(*a);
    });
}

}  // namespace avsplat::cli
