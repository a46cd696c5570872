// `avsplat eval scaling|tradeoff|stability [-o DIR] [--quick]`: regenerates one evaluation
// report (CSV, PNG plot, markdown table) by running the Python module avsplat.evaluation, which
// drives the library through its bindings:
//   <python> -m avsplat.evaluation REPORT -o DIR [--quick]
// The process is replaced by Python (exec), so its output, errors and exit code are the report's.
// The package is looked up in the build tree's python directory (where the build assembles it),
// then in the installed location; the interpreter is the one the build was configured with.
#include "commands.h"

#include "avsplat/core/error.h"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#ifndef AVSPLAT_PYTHON_EXECUTABLE
#define AVSPLAT_PYTHON_EXECUTABLE "/usr/bin/python3"
#endif

namespace avsplat::cli {

namespace {

struct EvalArgs {
    std::string report;
    std::string out_dir = ".";
    bool quick = false;
};

bool readable(const std::string& path) { return std::ifstream(path).good(); }

std::string find_package_dir() {
    std::vector<std::string> candidates;
#ifdef AVSPLAT_BUILD_PYTHON_DIR
    candidates.push_back(AVSPLAT_BUILD_PYTHON_DIR);
#endif
#ifdef AVSPLAT_INSTALL_PYTHON_DIR
    candidates.push_back(AVSPLAT_INSTALL_PYTHON_DIR);
#endif
    std::string tried;
    for (const std::string& dir : candidates) {
        if (readable(dir + "/avsplat/evaluation.py") && readable(dir + "/avsplat/__init__.py")) return dir;
        tried += (tried.empty() ? "" : ", ") + dir;
    }
    throw IOError("eval: the avsplat Python package was not found (looked in " +
                  (tried.empty() ? std::string("no location") : tried) +
                  "); build with AVSPLAT_WITH_PYTHON=ON or install avsplat");
}

[[noreturn]] void run_eval(const EvalArgs& a) {
    const std::string python = AVSPLAT_PYTHON_EXECUTABLE;
    if (access(python.c_str(), X_OK) != 0)
        throw IOError("eval: cannot run the Python interpreter " + python + ": " + std::strerror(errno));
    const std::string dir = find_package_dir();
    const char* old = std::getenv("PYTHONPATH");
    const std::string path = dir + (old && *old ? ":" + std::string(old) : std::string());
    if (setenv("PYTHONPATH", path.c_str(), 1) != 0) throw IOError("eval: cannot set PYTHONPATH");
    std::vector<std::string> args = {python, "-m", "avsplat.evaluation", a.report, "-o", a.out_dir};
    if (a.quick) args.emplace_back("--quick");
    std::vector<char*> argv;
    for (std::string& s : args) argv.push_back(s.data());
    argv.push_back(nullptr);
    std::fflush(stdout);
    execv(python.c_str(), argv.data());
    throw IOError("eval: cannot run " + python + ": " + std::strerror(errno));
}

}  // namespace

void add_eval(CLI::App& app) {
    auto* cmd = app.add_subcommand(
        "eval",
        "Regenerate an evaluation report (CSV, PNG, markdown): scaling (views x fusion policy), tradeoff "
        "(error vs run time) or stability (stiff and extreme cases vs float64)");
    auto a = std::make_shared<EvalArgs>();
    cmd->add_option("report", a->report, "scaling, tradeoff or stability")
        ->required()
        ->check(CLI::IsMember({"scaling", "tradeoff", "stability"}));
    cmd->add_option("-o,--output-dir", a->out_dir, "directory for <report>.csv, .png and .md")->capture_default_str();
    cmd->add_flag("--quick", a->quick, "tiny settings (seconds; for smoke tests, not for conclusions)");
    cmd->callback([a] { run_eval(*a); });
}

}  // namespace avsplat::cli
