// avsplat command-line tool: one subcommand per job (see --help).
#include "avsplat/gaussians.h"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
    CLI::App app{"avsplat: fuse, render, inspect and export feed-forward 3D Gaussian splats"};
    app.require_subcommand(1);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    }
    return 0;
}
