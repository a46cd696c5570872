// The web viewer's pages (view/web_viewer.h): the installed template with the configuration,
// the scene and the bundle put in.
#include "avsplat/view/web_viewer.h"

#include "avsplat/core/error.h"
#include "avsplat/core/framing.h"
#include "avsplat/io/atomic_file.h"
#include "avsplat/io/ply.h"
#include "avsplat/render/render.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <sys/stat.h>
#include <unistd.h>

namespace avsplat {
namespace {

const char* const kTemplate = "viewer.html";
const char* const kBundle = "avsplat-viewer.js";

bool is_file(const std::string& path) {
    struct stat st {};
    return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

std::string read_text(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot be read (the web viewer's files; reinstall with scripts/web_viewer.sh)");
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

std::string base64(const std::string& bytes) {
    static const char* const digits = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    out.reserve((bytes.size() + 2) / 3 * 4);
    std::size_t i = 0;
    for (; i + 3 <= bytes.size(); i += 3) {
        const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) |
                           (static_cast<unsigned char>(bytes[i + 1]) << 8) | static_cast<unsigned char>(bytes[i + 2]);
        out += digits[v >> 18];
        out += digits[(v >> 12) & 63];
        out += digits[(v >> 6) & 63];
        out += digits[v & 63];
    }
    if (i < bytes.size()) {
        const bool two = i + 1 < bytes.size();
        const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) |
                           (two ? static_cast<unsigned char>(bytes[i + 1]) << 8 : 0u);
        out += digits[v >> 18];
        out += digits[(v >> 12) & 63];
        out += two ? digits[(v >> 6) & 63] : '=';
        out += '=';
    }
    return out;
}

// Text inside a <script> element ends at the first "</script" (any case) and must not contain
// "<!--": JSON and base64 can be escaped, the bundle (esbuild escapes both) is checked.
std::string script_safe_json(const nlohmann::json& j) {
    std::string text = j.dump();
    std::string out;
    out.reserve(text.size());
    for (char c : text) {
        if (c == '<') out += "\\u003c";
        else out += c;
    }
    return out;
}

void check_options(const Camera& camera, const WebViewerOptions& o) {
    auto invalid = [](const std::string& what) { throw std::invalid_argument("web viewer: " + what); };
    if (camera.width < 1 || camera.height < 1) invalid("camera: width and height must be >= 1");
    if (!(camera.fx > 0.0 && camera.fy > 0.0) || !std::isfinite(camera.fx) || !std::isfinite(camera.fy))
        invalid("camera: fx and fy must be finite and > 0");
    if (!std::isfinite(camera.cx) || !std::isfinite(camera.cy)) invalid("camera: cx and cy must be finite");
    if (!camera.world_to_camera.allFinite()) invalid("camera: world_to_camera must be finite");
    if (!(camera.near > 0.0 && camera.far > camera.near)) invalid("camera: near must be > 0 and far > near");
    for (int c = 0; c < 3; ++c)
        if (!(o.background[c] >= 0.0f && o.background[c] <= 1.0f))
            invalid("background[" + std::to_string(c) + "]: must be in [0, 1]");
    if (!o.up.allFinite() || o.up.norm() == 0.0) invalid("up: must be finite and non-zero");
    if (o.target && !o.target->allFinite()) invalid("target: must be finite");
}

Eigen::Vector3d orbit_target(const GaussianCloud& cloud, const Camera& camera, const WebViewerOptions& o) {
    if (o.target) return *o.target;
    const Eigen::Vector3d eye = camera.position();
    const Eigen::Vector3d forward = camera.world_to_camera.block<1, 3>(2, 0).transpose().normalized();
    double ahead = 1.0;
    if (cloud.size() > 0) {
        const auto bounds = robust_bounds(cloud);
        const double along = (0.5 * (bounds.first + bounds.second) - eye).dot(forward);
        if (along > 0.0) ahead = along;
    }
    return eye + ahead * forward;
}

nlohmann::json page_config(const GaussianCloud& cloud, const Camera& camera, const WebViewerOptions& o,
                           const nlohmann::json& scene) {
    check_options(camera, o);
    nlohmann::json w2c = nlohmann::json::array();
    for (int r = 0; r < 4; ++r) {
        nlohmann::json row = nlohmann::json::array();
        for (int c = 0; c < 4; ++c) row.push_back(camera.world_to_camera(r, c));
        w2c.push_back(row);
    }
    const Eigen::Vector3d target = orbit_target(cloud, camera, o);
    const RenderOptions conventions;  // the CPU renderer's 3DGS defaults, which the page follows
    return {
        {"scene", scene},
        {"camera",
         {{"world_to_camera", w2c}, {"fx", camera.fx}, {"fy", camera.fy}, {"cx", camera.cx}, {"cy", camera.cy},
          {"width", camera.width}, {"height", camera.height}, {"near", camera.near}, {"far", camera.far}}},
        {"background", {o.background[0], o.background[1], o.background[2]}},
        {"up", {o.up.x(), o.up.y(), o.up.z()}},
        {"target", {target.x(), target.y(), target.z()}},
        {"render",
         {{"low_pass", conventions.low_pass},
          {"extent_sigma", conventions.extent_sigma},
          {"alpha_threshold", conventions.alpha_threshold}}},
    };
}

std::string html_escape(const std::string& text) {
    std::string out;
    for (char c : text) {
        switch (c) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            default: out += c;
        }
    }
    return out;
}

// Puts the pieces into the template; each placeholder must occur exactly once.
std::string fill_template(const std::string& viewer_dir, const std::string& title, const std::string& config,
                          const std::string& scene_text) {
    const std::string template_path = viewer_dir + "/" + kTemplate;
    const std::string bundle_path = viewer_dir + "/" + kBundle;
    std::string page = read_text(template_path);
    const std::string bundle = read_text(bundle_path);
    for (const char* marker : {"</script", "</SCRIPT", "<!--"})
        if (bundle.find(marker) != std::string::npos)
            throw IOError(bundle_path + ": contains \"" + marker + "\", which would end the page's script early");
    const std::pair<const char*, const std::string*> parts[] = {
        {"{{AVSPLAT_TITLE}}", &title},
        {"{{AVSPLAT_CONFIG}}", &config},
        {"{{AVSPLAT_SCENE}}", &scene_text},
        {"{{AVSPLAT_BUNDLE}}", &bundle},
    };
    // Find every placeholder first (in the template alone), then assemble front to back, so
    // that nothing put in is ever searched.
    std::vector<std::pair<std::size_t, std::size_t>> at;  // (position, part index)
    for (std::size_t k = 0; k < 4; ++k) {
        const std::size_t pos = page.find(parts[k].first);
        if (pos == std::string::npos || page.find(parts[k].first, pos + 1) != std::string::npos)
            throw IOError(template_path + ": must hold " + parts[k].first + " exactly once");
        at.emplace_back(pos, k);
    }
    std::sort(at.begin(), at.end());
    std::string out;
    out.reserve(page.size() + bundle.size() + scene_text.size() + config.size() + title.size());
    std::size_t from = 0;
    for (const auto& [pos, k] : at) {
        out.append(page, from, pos - from);
        out += *parts[k].second;
        from = pos + std::char_traits<char>::length(parts[k].first);
    }
    out.append(page, from, std::string::npos);
    return out;
}

}  // namespace

std::vector<std::string> web_viewer_search_path() {
    if (const char* dir = std::getenv("AVSPLAT_WEB_VIEWER"); dir && *dir) return {dir};
    std::vector<std::string> dirs;
    // Relative to the running program, so that a moved install (bin/ beside share/) still works.
    std::string exe(4096, '\0');
    const ssize_t n = ::readlink("/proc/self/exe", exe.data(), exe.size() - 1);
    if (n > 0) {
        exe.resize(static_cast<std::size_t>(n));
        const std::size_t slash = exe.rfind('/');
        if (slash != std::string::npos) dirs.push_back(exe.substr(0, slash) + "/../share/avsplat/web-viewer");
    }
#ifdef AVSPLAT_WEB_VIEWER_BUILD_DIR
    dirs.push_back(AVSPLAT_WEB_VIEWER_BUILD_DIR);
#endif
#ifdef AVSPLAT_WEB_VIEWER_INSTALL_DIR
    dirs.push_back(AVSPLAT_WEB_VIEWER_INSTALL_DIR);
#endif
    return dirs;
}

std::string find_web_viewer() {
    const std::vector<std::string> dirs = web_viewer_search_path();
    std::string looked;
    for (const std::string& dir : dirs) {
        if (is_file(dir + "/" + kTemplate) && is_file(dir + "/" + kBundle)) return dir;
        looked += (looked.empty() ? "" : ", ") + dir;
    }
    const bool from_env = std::getenv("AVSPLAT_WEB_VIEWER") && *std::getenv("AVSPLAT_WEB_VIEWER");
    throw IOError(std::string("web viewer not installed: no ") + kTemplate + " and " + kBundle + " in " +
                  (from_env ? "AVSPLAT_WEB_VIEWER=" : "") + (looked.empty() ? "(no folder)" : looked) +
                  "; install it with `bash scripts/web_viewer.sh` in avsplat's source tree (needs npm), or set "
                  "AVSPLAT_WEB_VIEWER to the folder it printed");
}

std::string web_viewer_scene(const GaussianCloud& cloud) { return ply_bytes(cloud); }

std::string web_viewer_page(const GaussianCloud& cloud, const Camera& camera, const std::string& viewer_dir,
                            const WebViewerOptions& options) {
    const nlohmann::json config = page_config(cloud, camera, options, {{"type", "ply"}});
    return fill_template(viewer_dir, html_escape(options.title), script_safe_json(config),
                         base64(web_viewer_scene(cloud)));
}

std::string web_viewer_page_for_url(const GaussianCloud& cloud, const Camera& camera, const std::string& scene_url,
                                    const std::string& viewer_dir, const WebViewerOptions& options) {
    const nlohmann::json config = page_config(cloud, camera, options, {{"type", "ply"}, {"url", scene_url}});
    return fill_template(viewer_dir, html_escape(options.title), script_safe_json(config), "");
}

void write_html(const std::string& path, const GaussianCloud& cloud, const Camera& camera,
                const std::string& viewer_dir, const WebViewerOptions& options) {
    write_file_atomically(path, web_viewer_page(cloud, camera, viewer_dir, options));
}

}  // namespace avsplat
