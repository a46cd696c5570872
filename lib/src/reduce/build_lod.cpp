// build_lod: levels by repeated whole-scene simplification, then the LOD set writer.
#include "avsplat/reduce/build_lod.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace avsplat {

namespace {

constexpr int kMaxLevels = 64;
constexpr int kMaxAutomaticLevels = 16;

}  // namespace

LodBuild build_lod_levels(const GaussianCloud& cloud, const BuildLodOptions& options,
                          const std::vector<Camera>& cameras) {
    if (options.levels < 0 || options.levels > kMaxLevels)
        throw std::invalid_argument("BuildLodOptions.levels must be in 0..64 (0: automatic), got " +
                                    std::to_string(options.levels));
    if (!(options.ratio > 0 && options.ratio < 1))
        throw std::invalid_argument("BuildLodOptions.ratio must be in (0, 1), got " + std::to_string(options.ratio));
    if (options.levels == 0 && options.coarsest == 0)
        throw std::invalid_argument("BuildLodOptions.coarsest must be >= 1");
    validate(cloud);
    LodBuild out;
    out.levels.push_back(cloud);
    out.seconds.push_back(0.0);
    out.errors.push_back(cameras.empty() ? std::numeric_limits<double>::quiet_NaN() : 0.0);
    const int want = options.levels;
    if (options.progress) options.progress(0, want);
    for (int level = 1;; ++level) {
        const GaussianCloud& prev = out.levels.back();
        if (want > 0 && level >= want) break;
        if (want == 0 && (prev.size() <= options.coarsest || level >= kMaxAutomaticLevels)) break;
        const std::size_t target = std::max<std::size_t>(1, std::size_t(std::llround(options.ratio * double(prev.size()))));
        if (target >= prev.size() && want == 0) break;  // a level of one Gaussian
        SimplifyOptions s;
        s.target_count = target;
        s.method = options.method;
        const auto start = std::chrono::steady_clock::now();
        SimplifyResult r = simplify(prev, s, cameras);
        out.seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        out.errors.push_back(r.error);
        out.levels.push_back(std::move(r.cloud));
        if (options.progress) options.progress(level, want);
    }
    return out;
}

LodBuild build_lod(const GaussianCloud& cloud, const std::string& path, const BuildLodOptions& options,
                   const LodWriteOptions& write, const std::vector<Camera>& cameras) {
    LodBuild out = build_lod_levels(cloud, options, cameras);
    write_lod_set(path, out.levels, write);
    return out;
}

}  // namespace avsplat
