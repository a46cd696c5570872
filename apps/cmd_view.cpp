// `avsplat view SCENE`: serves the web viewer (view/web_viewer.h) and the scene on 127.0.0.1,
// prints the URL and opens a browser where there is one, until Ctrl-C. Nothing is fetched from
// the network: the page carries the installed viewer, the scene comes from this server. Ctrl-C
// stops it within 200 ms, with the exit code of any interrupted command (130).
#include "commands.h"
#include "input_checks.h"
#include "input_formats.h"
#include "local_http_server.h"
#include "viewer_camera.h"
#include "avsplat/predictions/prediction_npz.h"

#include "avsplat/core/error.h"
#include "avsplat/core/interrupt.h"
#include "avsplat/view/web_viewer.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

extern char** environ;

namespace avsplat::cli {
namespace {

struct ViewArgs {
    std::string input;
    int port = 0;
    bool no_open = false;
    CameraArgs cameras;
};

// Starts the user's browser on `url` without waiting for it: $BROWSER when set, else xdg-open
// (macOS: open) where a display is; returns its process id, or 0 when there is none to start.
pid_t open_browser(const std::string& url) {
    std::string program;
    if (const char* b = std::getenv("BROWSER"); b && *b) {
        program = b;
    } else {
#ifdef __APPLE__
        program = "open";
#else
        const char* x = std::getenv("DISPLAY");
        const char* w = std::getenv("WAYLAND_DISPLAY");
        if ((!x || !*x) && (!w || !*w)) return 0;
        program = "xdg-open";
#endif
    }
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    std::string arg0 = program, arg1 = url;
    char* argv[] = {arg0.data(), arg1.data(), nullptr};
    pid_t pid = 0;
    const int err = posix_spawnp(&pid, program.c_str(), &actions, nullptr, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    return err == 0 ? pid : 0;
}

void run_view(const ViewArgs& a) {
    const std::string viewer = find_web_viewer();  // before the work: a missing viewer fails at once
    const GaussianCloud cloud = read_gaussian_input(a.input);
    auto [camera, options] = resolve_viewer_camera(a.cameras, cloud);
    options.title = a.input + " - avsplat viewer";
    LocalHttpServer server(a.port);
    const std::map<std::string, HttpResource> resources = {
        {"/", {"text/html; charset=utf-8", web_viewer_page_for_url(cloud, camera, "scene.ply", viewer, options)}},
        {"/scene.ply", {"application/octet-stream", web_viewer_scene(cloud)}},
    };
    const std::string url = "http://127.0.0.1:" + std::to_string(server.port()) + "/";
    std::printf("serving %s (%zu Gaussians) at %s (Ctrl-C stops)\n", a.input.c_str(), cloud.size(), url.c_str());
    pid_t browser = 0;
    if (!a.no_open) {
        browser = open_browser(url);
        if (browser == 0) std::printf("no browser to open here (no DISPLAY or BROWSER): open the URL above\n");
    }
    std::fflush(stdout);
    // Until Ctrl-C (or SIGTERM): Interrupted ends the command with 130 (143), as any other.
    server.serve(resources, [&] {
        if (browser > 0 && ::waitpid(browser, nullptr, WNOHANG) == browser) browser = 0;
        throw_if_interrupted();
    });
}

}  // namespace

void add_view(CLI::App& app) {
    auto* cmd = app.add_subcommand(
        "view", "Show Gaussians in the browser: serve the web viewer and the scene on 127.0.0.1 until Ctrl-C");
    auto a = std::make_shared<ViewArgs>();
    cmd->add_option("input", a->input, "input Gaussians: " + readable_formats(true))->required()->check(existing_input(true));
    cmd->add_option("--port", a->port, "port on 127.0.0.1 (default 0: a free one the system picks)")
        ->check(CLI::Range(0, 65535));
    cmd->add_flag("--no-open", a->no_open, "only print the URL; do not start a browser");
    add_viewer_camera_options(*cmd, a->cameras, "Initial camera (none given: the default framing)");
    cmd->callback([a] { run_view(*a); });
}

}  // namespace avsplat::cli
