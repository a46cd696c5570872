// Subcommands of the avsplat tool. Each add_* registers one subcommand and its callback; the
// callback throws on failure and main() turns that into one line on stderr and exit code 1.
#pragma once

#include <CLI/CLI.hpp>

namespace avsplat::cli {

void add_info(CLI::App& app);
void add_convert(CLI::App& app);
void add_fuse(CLI::App& app);
void add_render(CLI::App& app);
void add_eval(CLI::App& app);
void add_prune(CLI::App& app);
void add_simplify(CLI::App& app);
void add_lod(CLI::App& app);
void add_cameras(CLI::App& app);
void add_view(CLI::App& app);
void add_stitch(CLI::App& app);
#ifdef AVSPLAT_WITH_OPEN3D
void add_demo(CLI::App& app);  // needs the simulator (Open3D ray casting)
#endif

}  // namespace avsplat::cli
