#include "io/sog/sog_meta.h"

#include "avsplat/core/error.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <limits>

namespace avsplat::sog {

namespace {

using nlohmann::json;

/// meta.json is four levels deep; anything much deeper is not a SOG.
constexpr int kMaxJsonDepth = 16;

struct Reader {
    const std::string& where;

    [[noreturn]] void fail(const std::string& field, const std::string& what) const {
        throw IOError(where + ": \"" + field + "\" " + what);
    }

    const json& member(const json& obj, const char* key, const std::string& field) const {
        auto it = obj.find(key);
        if (it == obj.end()) fail(field, "is missing");
        return *it;
    }

    const json& object(const json& obj, const char* key, const std::string& field) const {
        const json& v = member(obj, key, field);
        if (!v.is_object()) fail(field, "must be an object");
        return v;
    }

    double number(const json& v, const std::string& field) const {
        if (!v.is_number()) fail(field, "must be a number, got " + v.dump().substr(0, 64));
        const double d = v.get<double>();
        if (!std::isfinite(d)) fail(field, "must be finite");
        return d;
    }

    std::size_t whole(const json& v, const std::string& field, std::size_t lo, std::size_t hi) const {
        if (!v.is_number()) fail(field, "must be a whole number, got " + v.dump().substr(0, 64));
        const double d = v.get<double>();
        if (!(d >= double(lo) && d <= double(hi)) || d != std::floor(d))
            fail(field, "must be a whole number in " + std::to_string(lo) + ".." + std::to_string(hi) +
                            ", got " + v.dump().substr(0, 64));
        return static_cast<std::size_t>(d);
    }

    std::array<double, 3> triple(const json& obj, const char* key, const std::string& field) const {
        const json& v = member(obj, key, field);
        if (!v.is_array() || v.size() != 3) fail(field, "must be an array of 3 numbers");
        std::array<double, 3> out{};
        for (std::size_t k = 0; k < 3; ++k) out[k] = number(v[k], field + "[" + std::to_string(k) + "]");
        return out;
    }

    std::vector<float> codebook(const json& obj, const std::string& field) const {
        const json& v = member(obj, "codebook", field + ".codebook");
        if (!v.is_array() || v.size() != kCodebookSize)
            fail(field + ".codebook", "must be an array of " + std::to_string(kCodebookSize) + " numbers");
        std::vector<float> out(kCodebookSize);
        for (std::size_t k = 0; k < kCodebookSize; ++k) {
            const std::string f = field + ".codebook[" + std::to_string(k) + "]";
            const double d = number(v[k], f);
            if (std::fabs(d) > double(std::numeric_limits<float>::max())) fail(f, "does not fit float32");
            out[k] = static_cast<float>(d);
        }
        return out;
    }

    // A plain file name: what a folder or a zip holds beside meta.json. Anything else could make
    // the folder reader open a file outside the SOG's folder.
    std::string file_name(const json& v, const std::string& field) const {
        if (!v.is_string()) fail(field, "must be a string");
        const std::string s = v.get<std::string>();
        if (s.empty() || s.size() > 255 || s == "." || s == ".." ||
            s.find_first_of(std::string("/\\\0", 3)) != std::string::npos)
            fail(field, "must be a plain file name (no '/', '\\' or \"..\"), got \"" + s.substr(0, 64) + "\"");
        return s;
    }

    template <std::size_t K>
    std::array<std::string, K> files(const json& obj, const std::string& field) const {
        const json& v = member(obj, "files", field + ".files");
        if (!v.is_array() || v.size() < K)
            fail(field + ".files", "must be an array of " + std::to_string(K) + " file names");
        std::array<std::string, K> out;
        for (std::size_t k = 0; k < K; ++k)
            out[k] = file_name(v[k], field + ".files[" + std::to_string(k) + "]");
        return out;
    }
};


// splat-transform before 1.0: {"means": {"shape": [N, 3], "dtype", "mins", "maxs", "files"},
// "scales": {.. "mins", "maxs" (3 log scales)}, "quats": {.. "encoding": "quaternion_packed"},
// "sh0": {.. "mins", "maxs" (4: RGB and the opacity logit)}, optional "shN": {"mins", "maxs"
// (numbers), "files": [centroids, labels]}}.
template <std::size_t K>
std::array<double, K> numbers(const Reader& r, const json& obj, const char* key, const std::string& field) {
    const json& v = r.member(obj, key, field);
    if (!v.is_array() || v.size() != K) r.fail(field, "must be an array of " + std::to_string(K) + " numbers");
    std::array<double, K> out{};
    for (std::size_t k = 0; k < K; ++k) out[k] = r.number(v[k], field + "[" + std::to_string(k) + "]");
    return out;
}

template <std::size_t K>
void check_ordered(const Reader& r, const std::array<double, K>& lo, const std::array<double, K>& hi,
                   const std::string& field) {
    for (std::size_t k = 0; k < K; ++k)
        if (!(lo[k] <= hi[k])) r.fail(field + ".mins[" + std::to_string(k) + "]", "is greater than " + field + ".maxs");
}

Meta parse_meta_v1(const json& root, const Reader& r, std::size_t max_gaussians) {
    Meta m;
    m.version = 1;
    const json& means = r.object(root, "means", "means");
    if (!means.contains("shape"))
        r.fail("means.shape", "is missing (no \"version\": read as a SOG version 1 meta.json, which has it)");
    const json& shape = means["shape"];
    if (!shape.is_array() || shape.empty())
        r.fail("means.shape", "must be an array [count, 3] (a SOG version 1 meta.json: no \"version\")");
    m.count = r.whole(shape[0], "means.shape[0]", 0, max_gaussians);
    m.means_mins = r.triple(means, "mins", "means.mins");
    m.means_maxs = r.triple(means, "maxs", "means.maxs");
    check_ordered(r, m.means_mins, m.means_maxs, "means");
    m.means_files = r.files<2>(means, "means");

    const json& scales = r.object(root, "scales", "scales");
    m.scales_mins = numbers<3>(r, scales, "mins", "scales.mins");
    m.scales_maxs = numbers<3>(r, scales, "maxs", "scales.maxs");
    check_ordered(r, m.scales_mins, m.scales_maxs, "scales");
    m.scales_file = r.files<1>(scales, "scales")[0];

    m.quats_file = r.files<1>(r.object(root, "quats", "quats"), "quats")[0];

    const json& sh0 = r.object(root, "sh0", "sh0");
    m.sh0_mins = numbers<4>(r, sh0, "mins", "sh0.mins");
    m.sh0_maxs = numbers<4>(r, sh0, "maxs", "sh0.maxs");
    check_ordered(r, m.sh0_mins, m.sh0_maxs, "sh0");
    m.sh0_file = r.files<1>(sh0, "sh0")[0];

    auto shn = root.find("shN");
    if (shn != root.end() && !shn->is_null()) {
        if (!shn->is_object()) r.fail("shN", "must be an object");
        m.shn_min = r.number(r.member(*shn, "mins", "shN.mins"), "shN.mins");
        m.shn_max = r.number(r.member(*shn, "maxs", "shN.maxs"), "shN.maxs");
        if (!(m.shn_min <= m.shn_max)) r.fail("shN.mins", "is greater than shN.maxs");
        m.shn_files = r.files<2>(*shn, "shN");
        m.has_shn = true;
    }
    return m;
}

}  // namespace

Meta parse_meta(const std::string& text, const std::string& where, std::size_t max_gaussians) {
    if (text.size() > kMaxMetaBytes)
        throw IOError(where + ": " + std::to_string(text.size()) + " bytes, more than a SOG meta.json holds (" +
                      std::to_string(kMaxMetaBytes) + ")");
    json root;
    try {
        root = json::parse(text, [&where](int depth, json::parse_event_t, json&) {
            if (depth > kMaxJsonDepth)
                throw IOError(where + ": JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
            return true;
        });
    } catch (const json::exception& e) {
        throw IOError(where + ": not valid JSON: " + e.what());
    }
    const Reader r{where};
    if (!root.is_object()) throw IOError(where + ": not a JSON object");
    auto version = root.find("version");
    if (version == root.end()) return parse_meta_v1(root, r, max_gaussians);
    if (!version->is_number() || version->get<double>() != 2.0)
        r.fail("version", "is " + version->dump().substr(0, 32) + ", avsplat reads versions 1 (no \"version\") and 2");

    Meta m;
    m.count = r.whole(r.member(root, "count", "count"), "count", 0, max_gaussians);

    const json& means = r.object(root, "means", "means");
    m.means_mins = r.triple(means, "mins", "means.mins");
    m.means_maxs = r.triple(means, "maxs", "means.maxs");
    for (int a = 0; a < 3; ++a)
        if (!(m.means_mins[a] <= m.means_maxs[a]))
            r.fail("means.mins[" + std::to_string(a) + "]", "is greater than means.maxs");
    m.means_files = r.files<2>(means, "means");

    const json& scales = r.object(root, "scales", "scales");
    m.scales_codebook = r.codebook(scales, "scales");
    m.scales_file = r.files<1>(scales, "scales")[0];

    m.quats_file = r.files<1>(r.object(root, "quats", "quats"), "quats")[0];

    const json& sh0 = r.object(root, "sh0", "sh0");
    m.sh0_codebook = r.codebook(sh0, "sh0");
    m.sh0_file = r.files<1>(sh0, "sh0")[0];

    auto shn = root.find("shN");
    if (shn != root.end() && !shn->is_null()) {
        if (!shn->is_object()) r.fail("shN", "must be an object");
        m.sh_bands = static_cast<int>(r.whole(r.member(*shn, "bands", "shN.bands"), "shN.bands", 1, 3));
        m.palette_count = r.whole(r.member(*shn, "count", "shN.count"), "shN.count", 1, kMaxPalette);
        m.shn_codebook = r.codebook(*shn, "shN");
        m.shn_files = r.files<2>(*shn, "shN");
        m.has_shn = true;
    }
    return m;
}

std::string format_meta(const Meta& m) {
    json root;
    root["version"] = 2;
    root["asset"] = {{"generator", "avsplat"}};
    root["count"] = m.count;
    root["means"] = {{"mins", m.means_mins}, {"maxs", m.means_maxs}, {"files", m.means_files}};
    root["scales"] = {{"codebook", m.scales_codebook}, {"files", json::array({m.scales_file})}};
    root["quats"] = {{"files", json::array({m.quats_file})}};
    root["sh0"] = {{"codebook", m.sh0_codebook}, {"files", json::array({m.sh0_file})}};
    if (m.has_shn)
        root["shN"] = {{"count", m.palette_count},
                       {"bands", m.sh_bands},
                       {"codebook", m.shn_codebook},
                       {"files", m.shn_files}};
    return root.dump();
}

}  // namespace avsplat::sog
