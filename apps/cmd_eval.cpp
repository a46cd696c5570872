// `avsplat eval REPORT [-o DIR] [--quick]`: regenerates one evaluation report (CSV, PNG plot,
// markdown table) by running the Python package avsplat.eval, which drives the library
// through its bindings:
//   <python> -m avsplat.eval REPORT -o DIR [--quick]
// Evaluation lives in Python, not here, because a report is mostly plotting (matplotlib) and
// table writing around a few library calls; the CLI only gives it the usual command-line entry.
// The process is replaced by Python (exec), so its output, errors and exit code are the report's.
// The interpreter is $AVSPLAT_PYTHON_EXECUTABLE when set (the console script of a pip install sets
// it to the interpreter that installed the package), else the one the build was configured
// with. The package directory (the one holding avsplat/) is, first found:
//   1. $AVSPLAT_PYTHON_DIR, when set (an explicit choice; it must hold the package);
//   2. next to this executable: <build>/apps/avsplat -> <build>/python (build tree), or
//      <prefix>/bin/avsplat -> <prefix>/<libdir>/python3/dist-packages (install tree);
//   3. the absolute build-tree and install locations this binary was configured with.
#include "commands.h"
#include "progress.h"

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

#ifndef AVSPLAT_EVAL_REPORTS
#error "AVSPLAT_EVAL_REPORTS (the keys of avsplat.eval.REPORTS) comes from apps/CMakeLists.txt"
#endif

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

bool holds_package(const std::string& dir) {
    return readable(dir + "/avsplat/__init__.py") && readable(dir + "/avsplat/eval/__init__.py");
}

// The directory of the running executable ("" when /proc/self/exe cannot be read).
std::string executable_dir() {
    std::vector<char> buf(4096);
    const ssize_t n = readlink("/proc/self/exe", buf.data(), buf.size() - 1);
    if (n <= 0) return {};
    std::string path(buf.data(), std::size_t(n));
    const std::size_t slash = path.rfind('/');
    return slash == std::string::npos ? std::string() : path.substr(0, slash);
}

std::string find_package_dir() {
    if (const char* dir = std::getenv("AVSPLAT_PYTHON_DIR"); dir && *dir) {
        if (holds_package(dir)) return dir;
        throw IOError(std::string("eval: AVSPLAT_PYTHON_DIR=") + dir +
                      " does not hold the avsplat Python package (avsplat/eval/__init__.py)");
    }
    std::vector<std::string> candidates;
    const std::string exe_dir = executable_dir();
    if (!exe_dir.empty()) {
#ifdef AVSPLAT_PYTHON_FROM_BUILD_EXE
        candidates.push_back(exe_dir + "/" AVSPLAT_PYTHON_FROM_BUILD_EXE);
#endif
#ifdef AVSPLAT_PYTHON_FROM_INSTALLED_EXE
        candidates.push_back(exe_dir + "/" AVSPLAT_PYTHON_FROM_INSTALLED_EXE);
#endif
    }
#ifdef AVSPLAT_BUILD_PYTHON_DIR
    candidates.push_back(AVSPLAT_BUILD_PYTHON_DIR);
#endif
#ifdef AVSPLAT_INSTALL_PYTHON_DIR
    candidates.push_back(AVSPLAT_INSTALL_PYTHON_DIR);
#endif
    std::string tried;
    for (const std::string& dir : candidates) {
        if (holds_package(dir)) return dir;
        tried += (tried.empty() ? "" : ", ") + dir;
    }
    throw IOError("eval: the avsplat Python package was not found (looked in " +
                  (tried.empty() ? std::string("no location") : tried) +
                  "); build with AVSPLAT_WITH_PYTHON=ON, install avsplat, or set AVSPLAT_PYTHON_DIR");
}

[[noreturn]] void run_eval(const EvalArgs& a) {
    const char* chosen = std::getenv("AVSPLAT_PYTHON_EXECUTABLE");
    const std::string python = chosen && *chosen ? chosen : AVSPLAT_PYTHON_EXECUTABLE;
    if (access(python.c_str(), X_OK) != 0)
        throw IOError("eval: cannot run the Python interpreter " + python + ": " + std::strerror(errno));
    const std::string dir = find_package_dir();
    const char* old = std::getenv("PYTHONPATH");
    const std::string path = dir + (old && *old ? ":" + std::string(old) : std::string());
    if (setenv("PYTHONPATH", path.c_str(), 1) != 0) throw IOError("eval: cannot set PYTHONPATH");
    // --quiet reaches the report's progress bars (avsplat.eval._common.Progress) through the environment.
    if (!Progress::shown() && setenv("AVSPLAT_QUIET", "1", 1) != 0) throw IOError("eval: cannot set AVSPLAT_QUIET");
    std::vector<std::string> args = {python, "-m", "avsplat.eval", a.report, "-o", a.out_dir};
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
        "eval", "Regenerate an evaluation report of avsplat.eval (CSV, PNG plot, markdown table)");
    auto a = std::make_shared<EvalArgs>();
    // The names are avsplat.eval.REPORTS (read at configure time, apps/CMakeLists.txt);
    // the Python package checks the name, so there is no second list to keep in step.
    cmd->add_option("report", a->report, "the report: " AVSPLAT_EVAL_REPORTS)->required();
    cmd->add_option("-o,--output-dir", a->out_dir, "directory for <report>.csv, .png and .md")->capture_default_str();
    cmd->add_flag("--quick", a->quick, "tiny settings (seconds; for smoke tests, not for conclusions)");
    cmd->callback([a] { run_eval(*a); });
}

}  // namespace avsplat::cli
