// avsplat command-line tool: one subcommand per job; `avsplat <command> --help` for each.
#include "commands.h"

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
    CLI::App app{"avsplat: fuse, render, inspect and export feed-forward 3D Gaussian splats"};
    app.require_subcommand(1);
    // Errors are one line on stderr (CLI11's `simple` adds a second, "Run with --help ...").
    app.failure_message([](const CLI::App*, const CLI::Error& e) {
        return std::string("avsplat: error: ") + e.what() + "\n";
    });
#ifdef AVSPLAT_WITH_OPEN3D
    avsplat::cli::add_demo(app);
#endif
    avsplat::cli::add_info(app);
    avsplat::cli::add_convert(app);
    avsplat::cli::add_fuse(app);
    avsplat::cli::add_render(app);
    avsplat::cli::add_eval(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "avsplat: error: %s\n", e.what());
        return 1;
    }
    return 0;
}
