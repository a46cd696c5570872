// avsplat command-line tool: one subcommand per job; `avsplat <command> --help` for each.
#include "commands.h"
#include "progress.h"

#include "avsplat/core/error.h"
#include "avsplat/core/interrupt.h"

#include <chrono>
#include <csignal>
#include <cstdio>
#include <exception>
#include <new>
#include <stdexcept>
#include <string>

namespace {

// Exit codes, documented in `avsplat --help`.
constexpr int kExitInternal = 1;  // a bug or an unexpected failure
constexpr int kExitUsage = 2;     // bad command line
constexpr int kExitInput = 3;     // an input file is missing, unreadable, malformed or has bad values
constexpr int kExitOutput = 4;    // an output file could not be written (the old file is kept)
constexpr int kExitMemory = 5;    // out of memory

// The signal (SIGINT, SIGTERM) that asked the tool to stop, or 0. Long library calls poll it
// through the interrupt check installed in main (avsplat/core/interrupt.h) and throw
// avsplat::Interrupted; unwinding removes the temporary files of unfinished outputs.
volatile std::sig_atomic_t stop_signal = 0;

extern "C" void on_stop_signal(int signo) { stop_signal = signo; }

int interrupted() {
    const int signo = stop_signal;
    std::fprintf(stderr, "avsplat: error: interrupted by %s; unfinished outputs were not written\n",
                 signo == SIGTERM ? "SIGTERM" : "SIGINT");
    return 128 + signo;
}

int fail(int code, const char* what) {
    std::fprintf(stderr, "avsplat: error: %s\n", what);
    return code;
}

}  // namespace

int main(int argc, char** argv) {
    // A file-size limit (ulimit -f) must give a write error with a message, not kill the tool.
    std::signal(SIGXFSZ, SIG_IGN);
    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
    const avsplat::ScopedInterruptCheck interrupt_check([] { return stop_signal != 0; }, std::chrono::nanoseconds(0));
    CLI::App app{"avsplat: fuse, render, inspect and export feed-forward 3D Gaussian splats"};
    app.footer(
        "Errors are one line on stderr; stdout carries only results. Exit codes: 0 success, 1 internal\n"
        "error, 2 usage error, 3 input error (a file missing, unreadable or malformed, or bad values),\n"
        "4 output error (a file could not be written; the previous file is left as it was), 5 out of memory,\n"
        "128 + N when stopped by signal N (130 SIGINT, 143 SIGTERM; unfinished outputs are not written).");
    app.set_version_flag("--version", AVSPLAT_VERSION, "Print the version (CMake's project version) and exit");
    app.require_subcommand(1);
    // Global flags may also follow the subcommand (`avsplat simplify ... --quiet`).
    app.fallthrough();
    app.add_flag_callback(
        "-q,--quiet", [] { avsplat::cli::Progress::set_quiet(true); },
        "No progress bars (they are drawn on stderr only when it is a terminal)");
    // Errors are one line on stderr (CLI11's `simple` adds a second, "Run with --help ...").
    // A missing subcommand names the ones there are (CLI11 says only "A subcommand is required").
    app.failure_message([](const CLI::App* top, const CLI::Error& e) {
        std::string line = std::string("avsplat: error: ") + e.what();
        if (dynamic_cast<const CLI::RequiredError*>(&e) && line.find("subcommand") != std::string::npos) {
            const CLI::App* at = top;  // the deepest command given, which lacks its subcommand
            for (bool deeper = true; deeper;) {
                deeper = false;
                for (const CLI::App* sub : at->get_subcommands())
                    if (sub->parsed()) {
                        at = sub;
                        deeper = true;
                        break;
                    }
            }
            std::string names;
            for (const CLI::App* sub : at->get_subcommands({})) names += (names.empty() ? "" : ", ") + sub->get_name();
            const std::string path = at == top ? "avsplat" : "avsplat " + at->get_name();
            line += ": " + names + " (" + path + " --help)";
        }
        return line + "\n";
    });
#ifdef AVSPLAT_WITH_OPEN3D
    avsplat::cli::add_demo(app);
#endif
    avsplat::cli::add_info(app);
    avsplat::cli::add_convert(app);
    avsplat::cli::add_fuse(app);
    avsplat::cli::add_render(app);
    avsplat::cli::add_eval(app);
    avsplat::cli::add_prune(app);
    avsplat::cli::add_simplify(app);
    avsplat::cli::add_lod(app);
    avsplat::cli::add_cameras(app);
    avsplat::cli::add_view(app);
    avsplat::cli::add_stitch(app);
    // CLI11 reports an unknown first word as "A subcommand is required"; name it instead.
    if (argc > 1 && argv[1][0] != '-') {
        std::string known;
        for (const CLI::App* sub : app.get_subcommands({})) {
            if (sub->get_name() == argv[1]) {
                known.clear();
                break;
            }
            known += (known.empty() ? "" : ", ") + sub->get_name();
        }
        if (!known.empty()) {
            std::fprintf(stderr, "avsplat: error: unknown subcommand '%s' (subcommands: %s; avsplat --help)\n", argv[1],
                         known.c_str());
            return kExitUsage;
        }
    }
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
        return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
        return app.exit(e);
    } catch (const CLI::ParseError& e) {
        app.exit(e);
        return kExitUsage;
    } catch (const avsplat::Interrupted&) {
        return interrupted();
    } catch (const avsplat::OutputError& e) {
        return fail(kExitOutput, e.what());
    } catch (const avsplat::IOError& e) {
        return fail(kExitInput, e.what());
    } catch (const std::invalid_argument& e) {
        return fail(kExitInput, e.what());
    } catch (const std::bad_alloc&) {
        return fail(kExitMemory, "out of memory");
    } catch (const std::exception& e) {
        return fail(kExitInternal, e.what());
    }
    // A signal that came after the last interruptible step: the outputs are complete, but the
    // caller asked to stop, so say so.
    if (stop_signal != 0) return interrupted();
    return 0;
}
