// Reading PlayCanvas LOD sets: lod-meta.json checked node by node, then each chosen level's SOGs.
#include "avsplat/io/lod_set.h"

#include "avsplat/core/error.h"
#include "io/input_file.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>

namespace avsplat {

namespace {

using nlohmann::json;

constexpr std::size_t kMaxMetaBytes = std::size_t(1) << 28;  // 10^6 leaves take about 150 MB
constexpr int kMaxLevels = 64;
constexpr int kMaxDepth = 128;

struct Range {
    std::size_t offset, count;
    std::string node;  // for errors
};

struct Parsed {
    LodSetInfo info;
    // Per file: its level (-1 none yet) and the ranges the tree gives it.
    std::vector<int> file_level;
    std::vector<std::vector<Range>> file_ranges;
};

std::string folder_of(const std::string& path) {
    const auto slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

struct Checker {
    const std::string& where;
    Parsed& p;

    [[noreturn]] void fail(const std::string& field, const std::string& what) const {
        throw IOError(where + ": \"" + field + "\" " + what);
    }

    std::size_t whole(const json& v, const std::string& field, double hi) const {
        if (!v.is_number() || !(v.get<double>() >= 0 && v.get<double>() <= hi) ||
            v.get<double>() != std::floor(v.get<double>()))
            fail(field, "must be a whole number in 0.." + std::to_string(static_cast<long long>(hi)) + ", got " +
                            v.dump().substr(0, 64));
        return static_cast<std::size_t>(v.get<double>());
    }

    std::array<float, 3> triple(const json& v, const std::string& field) const {
        if (!v.is_array() || v.size() != 3) fail(field, "must be an array of 3 numbers");
        std::array<float, 3> out{};
        for (std::size_t k = 0; k < 3; ++k) {
            if (!v[k].is_number() || !std::isfinite(v[k].get<double>()))
                fail(field + "[" + std::to_string(k) + "]", "must be a finite number");
            out[k] = static_cast<float>(v[k].get<double>());
        }
        return out;
    }

    void node(const json& n, const std::string& field, int depth) {
        if (depth > kMaxDepth) fail(field, "is nested deeper than " + std::to_string(kMaxDepth) + " levels");
        if (!n.is_object()) fail(field, "must be an object");
        p.info.depth = std::max(p.info.depth, depth);
        auto children = n.find("children");
        if (children != n.end() && !children->is_null()) {
            if (!children->is_array()) fail(field + ".children", "must be an array");
            for (std::size_t k = 0; k < children->size(); ++k)
                node((*children)[k], field + ".children[" + std::to_string(k) + "]", depth + 1);
        }
        auto lods = n.find("lods");
        if (lods == n.end() || lods->is_null()) return;
        if (!lods->is_object()) fail(field + ".lods", "must be an object");
        ++p.info.leaves;
        for (const auto& [key, ref] : lods->items()) {
            const std::string f = field + ".lods." + key;
            char* end = nullptr;
            const long level = std::strtol(key.c_str(), &end, 10);
            if (key.empty() || *end != '\0' || level < 0 || level >= p.info.levels)
                fail(f, "is not a level in 0.." + std::to_string(p.info.levels - 1));
            if (!ref.is_object()) fail(f, "must be an object {file, offset, count}");
            const json& entry = ref;  // a lambda may not capture a structured binding in C++17 (clang)
            auto member = [&](const char* k) -> const json& {
                auto it = entry.find(k);
                if (it == entry.end()) fail(f + "." + k, "is missing");
                return *it;
            };
            const std::size_t file = whole(member("file"), f + ".file", double(p.info.filenames.size()) - 1);
            const std::size_t offset = whole(member("offset"), f + ".offset", 9007199254740991.0);
            const std::size_t count = whole(member("count"), f + ".count", 9007199254740991.0);
            if (p.file_level[file] >= 0 && p.file_level[file] != int(level))
                fail(f + ".file", "is " + std::to_string(file) + " (" + p.info.filenames[file] + "), which level " +
                                      std::to_string(p.file_level[file]) + " uses too: a SOG holds one level");
            p.file_level[file] = int(level);
            p.file_ranges[file].push_back({offset, count, f});
            p.info.counts[level] += count;
        }
    }
};

// A file name of lod-meta.json: relative, and never above its folder.
void check_file_name(const std::string& name, const std::string& where, std::size_t k) {
    const std::string field = "\"filenames[" + std::to_string(k) + "]\"";
    if (name.empty() || name.size() > 1024 || name[0] == '/' || name.find('\\') != std::string::npos ||
        name.find('\0') != std::string::npos)
        throw IOError(where + ": " + field + " must be a relative path, got \"" + name.substr(0, 64) + "\"");
    std::size_t start = 0;
    while (start <= name.size()) {
        const std::size_t slash = std::min(name.find('/', start), name.size());
        const std::string part = name.substr(start, slash - start);
        if (part == ".." || part == "." || part.empty())
            throw IOError(where + ": " + field + " \"" + name.substr(0, 64) +
                          "\" must name a file inside the set's folder (no \"..\", \".\" or empty parts)");
        start = slash + 1;
    }
}

Parsed parse(const std::string& path) {
    const std::uint64_t size = io::regular_file_size(path);
    if (size > kMaxMetaBytes)
        throw IOError(path + ": " + std::to_string(size) + " bytes, more than a lod-meta.json is read (" +
                      std::to_string(kMaxMetaBytes) + ")");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading: " + std::strerror(errno));
    std::string text(static_cast<std::size_t>(size), '\0');
    if (size && !in.read(&text[0], static_cast<std::streamsize>(size))) throw IOError(path + ": read failed");
    json root;
    try {
        root = json::parse(text, [&path](int depth, json::parse_event_t, json&) {
            if (depth > 2 * kMaxDepth + 8)
                throw IOError(path + ": JSON nested deeper than " + std::to_string(2 * kMaxDepth + 8) + " levels");
            return true;
        });
    } catch (const json::exception& e) {
        throw IOError(path + ": not valid JSON: " + e.what());
    }
    Parsed p;
    Checker c{path, p};
    if (!root.is_object()) throw IOError(path + ": not a JSON object");
    auto version = root.find("version");
    if (version != root.end() && !(version->is_number() && version->get<double>() == 1.0))
        c.fail("version", "is " + version->dump().substr(0, 32) + ", avsplat reads lod-meta.json version 1");
    auto member = [&](const char* key) -> const json& {
        auto it = root.find(key);
        if (it == root.end()) c.fail(key, "is missing: not a LOD set");
        return *it;
    };
    const json& levels = member("lodLevels");
    if (!levels.is_number() || !(levels.get<double>() >= 1 && levels.get<double>() <= kMaxLevels) ||
        levels.get<double>() != std::floor(levels.get<double>()))
        c.fail("lodLevels", "must be a whole number in 1.." + std::to_string(kMaxLevels) + ", got " +
                                levels.dump().substr(0, 32));
    p.info.levels = levels.get<int>();
    p.info.counts.assign(std::size_t(p.info.levels), 0);
    const json& names = member("filenames");
    if (!names.is_array()) c.fail("filenames", "must be an array of strings");
    for (std::size_t k = 0; k < names.size(); ++k) {
        if (!names[k].is_string()) c.fail("filenames[" + std::to_string(k) + "]", "must be a string");
        p.info.filenames.push_back(names[k].get<std::string>());
        check_file_name(p.info.filenames.back(), path, k);
    }
    p.file_level.assign(names.size(), -1);
    p.file_ranges.resize(names.size());
    const json& tree = member("tree");
    c.node(tree, "tree", 0);
    auto bound = tree.find("bound");
    if (bound != tree.end() && bound->is_object() && bound->contains("min") && bound->contains("max")) {
        p.info.bound_min = c.triple((*bound)["min"], "tree.bound.min");
        p.info.bound_max = c.triple((*bound)["max"], "tree.bound.max");
    }
    auto counts = root.find("counts");
    if (counts != root.end()) {
        if (!counts->is_array() || counts->size() != std::size_t(p.info.levels))
            c.fail("counts", "must be an array of " + std::to_string(p.info.levels) + " numbers (lodLevels)");
        for (int l = 0; l < p.info.levels; ++l)
            if (c.whole((*counts)[l], "counts[" + std::to_string(l) + "]", 9007199254740991.0) != p.info.counts[l])
                c.fail("counts[" + std::to_string(l) + "]", "is " + (*counts)[l].dump() + " but the tree's leaves give level " +
                                                                std::to_string(l) + " " +
                                                                std::to_string(p.info.counts[l]) + " Gaussians");
    }
    // One SOG's ranges tile it without overlap.
    for (std::size_t f = 0; f < p.file_ranges.size(); ++f) {
        auto& r = p.file_ranges[f];
        std::sort(r.begin(), r.end(), [](const Range& a, const Range& b) { return a.offset < b.offset; });
        for (std::size_t k = 1; k < r.size(); ++k)
            if (r[k].offset < r[k - 1].offset + r[k - 1].count)
                c.fail(r[k].node + ".offset", "is " + std::to_string(r[k].offset) + ", inside the range of " +
                                                  r[k - 1].node + " in " + p.info.filenames[f]);
    }
    return p;
}

}  // namespace

LodSetInfo read_lod_set_info(const std::string& path) { return parse(path).info; }

std::vector<GaussianCloud> read_lod_set(const std::string& path, const std::vector<int>& levels) {
    const Parsed p = parse(path);
    std::vector<int> chosen;
    for (int l : levels) {
        const int level = l < 0 ? p.info.levels + l : l;
        if (level < 0 || level >= p.info.levels)
            throw IOError(path + ": level " + std::to_string(l) + " asked for, the set has levels 0.." +
                          std::to_string(p.info.levels - 1));
        chosen.push_back(level);
    }
    if (levels.empty())
        for (int l = 0; l < p.info.levels; ++l) chosen.push_back(l);
    const std::string folder = folder_of(path);
    std::map<int, GaussianCloud> cache;
    std::vector<GaussianCloud> out;
    for (int level : chosen) {
        if (!cache.count(level)) {
            std::vector<GaussianCloud> parts;
            for (std::size_t f = 0; f < p.info.filenames.size(); ++f) {
                if (p.file_level[f] != level) continue;
                const std::string sog = folder + "/" + p.info.filenames[f];
                GaussianCloud part = read_sog(sog);
                const auto& r = p.file_ranges[f];
                std::size_t sum = 0;
                for (const Range& range : r) sum += range.count;
                const std::size_t end = r.empty() ? 0 : r.back().offset + r.back().count;
                if (end > part.size())
                    throw IOError(path + ": \"" + r.back().node + "\" reaches row " + std::to_string(end) + " of " +
                                  sog + ", which holds " + std::to_string(part.size()) + " Gaussians");
                if (sum != part.size())
                    throw IOError(path + ": the tree gives " + sog + " " + std::to_string(sum) +
                                  " Gaussians, the SOG holds " + std::to_string(part.size()));
                parts.push_back(std::move(part));
            }
            if (parts.empty()) {
                GaussianCloud none(0, 0);
                cache.emplace(level, std::move(none));
            } else {
                cache.emplace(level, parts.size() == 1 ? std::move(parts[0]) : concatenate(parts));
            }
        }
        out.push_back(cache.at(level));
    }
    return out;
}

bool is_lod_set(const std::string& path) {
    try {
        const std::uint64_t size = io::regular_file_size(path);
        if (size > kMaxMetaBytes) return false;
        std::ifstream in(path, std::ios::binary);
        char first = 0;
        while (in.get(first) && std::isspace(static_cast<unsigned char>(first))) {
        }
        if (first != '{') return false;
        in.seekg(0);
        std::string text(static_cast<std::size_t>(size), '\0');
        if (!in.read(&text[0], static_cast<std::streamsize>(size))) return false;
        const json j = json::parse(text, nullptr, false);
        return j.is_object() && j.contains("lodLevels") && j.contains("filenames") && j.contains("tree");
    } catch (const std::exception&) {
        return false;
    }
}

}  // namespace avsplat
