// Writing PlayCanvas LOD sets: a kd-tree over the means of every level, leaves appended level by
// level to SOGs of about chunk_size Gaussians, lod-meta.json last.
#include "avsplat/io/lod_set.h"

#include "avsplat/core/error.h"
#include "avsplat/core/morton_order.h"
#include "avsplat/io/atomic_file.h"

#include <nlohmann/json.hpp>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace avsplat {

namespace {

using nlohmann::json;

// One Gaussian of some level: the flat index cum[level] + row.
struct Builder {
    const std::vector<GaussianCloud>& levels;
    const LodWriteOptions& options;
    std::vector<std::size_t> cum;               // first flat index of each level
    std::vector<std::size_t> flat;              // permuted by the tree build
    std::vector<std::vector<std::vector<std::size_t>>> units;  // level -> SOG -> rows
    std::vector<std::string> filenames;
    std::vector<std::vector<int>> unit_file;    // level -> SOG -> index in filenames

    int level_of(std::size_t g) const {
        return int(std::upper_bound(cum.begin(), cum.end(), g) - cum.begin()) - 1;
    }
    const float* mean(std::size_t g) const {
        const int l = level_of(g);
        return &levels[l].means[3 * (g - cum[l])];
    }

    // The box of half-sides the scales, rotated: |R| s per axis.
    void grow(double bmin[3], double bmax[3], const GaussianCloud& c, std::size_t i) const {
        const float* q = &c.rotations[4 * i];
        double w = q[0], x = q[1], y = q[2], z = q[3];
        const double n = std::sqrt(w * w + x * x + y * y + z * z);
        if (n > 0) w /= n, x /= n, y /= n, z /= n;
        const double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                                {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                                {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
        for (int a = 0; a < 3; ++a) {
            double half = 0;
            for (int k = 0; k < 3; ++k) half += std::fabs(R[a][k]) * c.scales[3 * i + k];
            const double m = c.means[3 * i + a];
            bmin[a] = std::min(bmin[a], m - half);
            bmax[a] = std::max(bmax[a], m + half);
        }
    }

    json leaf(std::size_t begin, std::size_t end) {
        std::vector<std::vector<std::size_t>> rows(levels.size());
        for (std::size_t k = begin; k < end; ++k) {
            const int l = level_of(flat[k]);
            rows[l].push_back(flat[k] - cum[l]);
        }
        double bmin[3], bmax[3];
        for (int a = 0; a < 3; ++a) {
            bmin[a] = std::numeric_limits<double>::infinity();
            bmax[a] = -std::numeric_limits<double>::infinity();
        }
        json lods = json::object();
        for (std::size_t l = 0; l < levels.size(); ++l) {
            if (rows[l].empty()) continue;
            for (std::size_t i : rows[l]) grow(bmin, bmax, levels[l], i);
            std::vector<std::size_t> ordered = morton_order(levels[l], std::move(rows[l]));
            auto& list = units[l];
            if (list.empty() || list.back().size() >= options.chunk_size) {
                list.emplace_back();
                unit_file[l].push_back(int(filenames.size()));
                filenames.push_back(std::to_string(l) + "_" + std::to_string(list.size() - 1) + "/meta.json");
            }
            lods[std::to_string(l)] = {{"file", unit_file[l].back()},
                                       {"offset", list.back().size()},
                                       {"count", ordered.size()}};
            list.back().insert(list.back().end(), ordered.begin(), ordered.end());
        }
        return {{"bound", {{"min", {float(bmin[0]), float(bmin[1]), float(bmin[2])}},
                           {"max", {float(bmax[0]), float(bmax[1]), float(bmax[2])}}}},
                {"lods", std::move(lods)}};
    }

    json node(std::size_t begin, std::size_t end) {
        if (end - begin <= options.node_size) return leaf(begin, end);
        double lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::numeric_limits<double>::infinity();
            hi[a] = -lo[a];
        }
        for (std::size_t k = begin; k < end; ++k) {
            const float* m = mean(flat[k]);
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], double(m[a]));
                hi[a] = std::max(hi[a], double(m[a]));
            }
        }
        int axis = 0;
        for (int a = 1; a < 3; ++a)
            if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
        // The median by (coordinate, flat index): the split does not depend on the sort's whims.
        const std::size_t mid = begin + (end - begin) / 2;
        std::nth_element(flat.begin() + std::ptrdiff_t(begin), flat.begin() + std::ptrdiff_t(mid),
                         flat.begin() + std::ptrdiff_t(end), [&](std::size_t a, std::size_t b) {
                             const float va = mean(a)[axis], vb = mean(b)[axis];
                             return va < vb || (va == vb && a < b);
                         });
        json left = node(begin, mid), right = node(mid, end);
        json bound = {{"min", json::array()}, {"max", json::array()}};
        for (int a = 0; a < 3; ++a) {
            bound["min"].push_back(std::min(left["bound"]["min"][a].get<float>(), right["bound"]["min"][a].get<float>()));
            bound["max"].push_back(std::max(left["bound"]["max"][a].get<float>(), right["bound"]["max"][a].get<float>()));
        }
        return {{"bound", std::move(bound)}, {"children", json::array({std::move(left), std::move(right)})}};
    }
};

std::string folder_of(const std::string& path) {
    const auto slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

void make_folder(const std::string& path) {
    if (::mkdir(path.c_str(), 0777) != 0 && errno != EEXIST)
        throw IOError(path + ": cannot create the folder: " + std::strerror(errno));
}

}  // namespace

void write_lod_set(const std::string& path, const std::vector<GaussianCloud>& levels, const LodWriteOptions& options) {
    if (levels.empty()) throw std::invalid_argument("write_lod_set: no levels");
    if (levels.size() > 64) throw std::invalid_argument("write_lod_set: more than 64 levels");
    if (options.node_size == 0) throw std::invalid_argument("write_lod_set: LodWriteOptions.node_size must be >= 1");
    if (options.chunk_size == 0) throw std::invalid_argument("write_lod_set: LodWriteOptions.chunk_size must be >= 1");
    if (path.size() < 5 || path.compare(path.size() - 5, 5, ".json") != 0)
        throw std::invalid_argument("write_lod_set: " + path + ": the path must be the lod-meta.json (ending in .json)");
    for (std::size_t l = 0; l < levels.size(); ++l) {
        try {
            validate(levels[l]);
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument("write_lod_set: level " + std::to_string(l) + ": " + e.what());
        }
        if (levels[l].sh_degree != levels[0].sh_degree)
            throw std::invalid_argument("write_lod_set: level " + std::to_string(l) + " has SH degree " +
                                        std::to_string(levels[l].sh_degree) + ", level 0 " +
                                        std::to_string(levels[0].sh_degree));
    }
    Builder b{levels, options, {}, {}, {}, {}, {}};
    b.cum.push_back(0);
    for (const auto& c : levels) b.cum.push_back(b.cum.back() + c.size());
    b.cum.pop_back();
    const std::size_t total = b.cum.back() + levels.back().size();
    b.flat.resize(total);
    for (std::size_t g = 0; g < total; ++g) b.flat[g] = g;
    b.units.resize(levels.size());
    b.unit_file.resize(levels.size());
    json tree = total ? b.node(0, total)
                      : json{{"bound", {{"min", {0, 0, 0}}, {"max", {0, 0, 0}}}}, {"lods", json::object()}};

    const std::string folder = folder_of(path);
    make_folder(folder);
    std::size_t written = 0, count = 0;
    for (const auto& list : b.units) count += list.size();
    SogWriteOptions sog = options.sog;
    sog.morton_order = false;
    if (options.progress) options.progress(0, count);
    for (std::size_t l = 0; l < levels.size(); ++l)
        for (std::size_t k = 0; k < b.units[l].size(); ++k) {
            const std::string unit = folder + "/" + std::to_string(l) + "_" + std::to_string(k);
            make_folder(unit);
            write_sog(unit, select(levels[l], b.units[l][k]), sog);
            if (options.progress) options.progress(++written, count);
        }

    json counts = json::array();
    for (const auto& c : levels) counts.push_back(c.size());
    const json meta = {{"version", 1},
                       {"asset",
                        {{"generator", "avsplat"},
                         {"chunkGaussians", options.chunk_size},
                         {"nodeGaussians", options.node_size}}},
                       {"count", total},
                       {"counts", std::move(counts)},
                       {"lodLevels", levels.size()},
                       {"lodErrors", false},
                       {"filenames", b.filenames},
                       {"tree", std::move(tree)}};
    write_file_atomically(path, meta.dump());
}

}  // namespace avsplat
