// build_lod: a level-of-detail set from one scene. Level 0 is the scene; level k+1 is level k
// simplified whole by the merge simplifier (reduce/simplify.h) to `ratio` of its count, so no
// level has seams at the tree's node borders. The levels are then cut into PlayCanvas's LOD
// octree and written as SOG chunks (io/lod_set.h).
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/io/lod_set.h"
#include "avsplat/reduce/simplify.h"

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace avsplat {

/// How build_lod makes the levels.
struct BuildLodOptions {
    /// Levels including level 0, 1..64; 0 (default): until the coarsest level holds at most
    /// `coarsest` Gaussians (at most 16 levels).
    int levels = 0;
    /// With levels = 0: the most Gaussians of the coarsest level (65536: one SOG of a few hundred
    /// kB, a scene a phone shows whole).
    std::size_t coarsest = 65536;
    /// Each level's count over the previous one's, in (0, 1).
    double ratio = 0.5;
    SimplifyMethod method = SimplifyMethod::Merge;
    /// Called after each level is made with (level, levels); levels is 0 while unknown.
    std::function<void(int, int)> progress;
};

/// What build_lod made.
struct LodBuild {
    std::vector<GaussianCloud> levels;   ///< level 0 (the input) first
    std::vector<double> seconds;         ///< the time to make each level (0 for level 0)
    std::vector<double> errors;          ///< simplify's rendered error of each level against the
                                         ///< previous one at the cameras; NaN without cameras
};

/// The levels of `cloud` (validated: std::invalid_argument naming field and index). `cameras`
/// are passed to simplify, which then measures each level's error. Throws std::invalid_argument
/// for options out of range; avsplat::Interrupted when the interrupt check says stop. Cost: about
/// twice one simplification of the input (the levels halve).
LodBuild build_lod_levels(const GaussianCloud& cloud, const BuildLodOptions& options = {},
                          const std::vector<Camera>& cameras = {});

/// build_lod_levels, then write_lod_set(path, levels, write).
LodBuild build_lod(const GaussianCloud& cloud, const std::string& path, const BuildLodOptions& options = {},
                   const LodWriteOptions& write = {}, const std::vector<Camera>& cameras = {});

}  // namespace avsplat
