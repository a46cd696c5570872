// Private: the codebooks of a SOG writer. Both are k-means (Lloyd) and deterministic: the result
// depends on the values, the options and the seed, never on the thread count.
//
//   Codebook1D   256 shared levels for one kind of value (log scales, SH degree 0, SH rest):
//                exact when the values take at most 256 distinct levels, else 1D k-means started
//                half way between the quantiles and even steps over the range, run to
//                convergence (at most kCodebookIterations), the level means computed from prefix
//                sums of the sorted values in double.
//   Palette      the SH palette (palette.cpp): k-means of the per-Gaussian SH-rest vectors;
//                initial centres are distinct Gaussians drawn by a seeded generator; each
//                iteration moves every centre to the mean of its vectors (summed in double, in
//                index order; an emptied centre is re-seeded on a Gaussian drawn by the same
//                generator) and assigns every vector to a centre. Exhaustive: the nearest, a
//                brute-force search in blocks of 64 vectors against all centres (vectorised),
//                skipped for the vectors that Hamerly's bounds show cannot have changed centre.
//                Grouped (large problems, PaletteSearch): the centres form about sqrt(k) groups
//                (a coarse k-means of the centres, a few Lloyd steps, then one per iteration)
//                and each vector takes the nearest centre of the kProbes = 8 groups whose
//                centroids are nearest to it (the inverted-file search of approximate nearest-
//                neighbour libraries): (1 + 8) sqrt(k) centres instead of k. Both searches stop
//                for a vector once it lies on a centre (within float rounding), and a block of
//                vectors once all do: equal vectors (higher bands all 0) cost one centre each.
//                The vectors are first scaled by a power of two (exact) so that their largest
//                |value| is in [1, 2): the float squares neither overflow nor underflow. Each
//                vector's search depends on that vector and the centres only, so threads split
//                the work without changing the result.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat::sog {

/// Most Lloyd iterations of a 1D codebook (each costs O(256 log N); it usually converges sooner).
constexpr int kCodebookIterations = 1000;

struct Codebook1D {
    std::vector<float> levels;  // 256, ascending

    /// Index of the level nearest to v (ties to the higher); -inf gives 0, +inf 255.
    std::uint8_t label(float v) const;

    std::vector<double> mids_;  // midpoints between consecutive levels
};

/// Fits 256 levels to `values` (NaN not allowed; -inf allowed: it gets a level of its own, 20
/// below the smallest finite value, so that exp() of it is effectively 0, as splat-transform does).
Codebook1D fit_codebook(const std::vector<float>& values);

struct Palette {
    std::size_t size = 0;               // entries
    std::vector<float> centres;         // size x dims
    std::vector<std::uint32_t> labels;  // per vector
};

/// How fit_palette finds each vector's entry.
enum class PaletteSearch {
    Auto,        ///< Grouped where grouped_palette_search says so, else Exhaustive
    Exhaustive,  ///< the nearest entry (up to float rounding)
    Grouped,     ///< the nearest among the entries of the groups the vector's nearest group lists
};

/// Auto's rule: Grouped from palettes of kGroupedMinPalette entries on, when one exhaustive pass
/// (n x k x dims multiply-adds) is above kGroupedMinWork.
constexpr std::size_t kGroupedMinPalette = 1024;
constexpr double kGroupedMinWork = 3e10;
bool grouped_palette_search(std::size_t n, std::size_t k, int dims);

/// k-means of n vectors of `dims` floats (row-major at `points`) into min(k, n) centres with
/// `iterations` Lloyd iterations, then a final assignment. With n <= k every vector is its own
/// entry.
Palette fit_palette(const float* points, std::size_t n, int dims, std::size_t k, int iterations,
                    std::uint64_t seed, PaletteSearch how = PaletteSearch::Auto);

}  // namespace avsplat::sog
