// Private: SOG's meta.json, parsed and checked (version 2, and version 1: splat-transform before
// 1.0), and written (version 2).
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace avsplat::sog {

/// Entries of every 1D codebook (scales, sh0, shN).
constexpr std::size_t kCodebookSize = 256;
/// Palette entries per row of shN_centroids.webp.
constexpr int kPaletteRow = 64;
/// Most palette entries: labels are 16 bits.
constexpr std::size_t kMaxPalette = 65536;
/// Largest meta.json read (codebooks of 3 x 256 numbers take a few kB).
constexpr std::size_t kMaxMetaBytes = std::size_t(1) << 22;

struct Meta {
    /// 2: codebooks. 1: no "version" field; per-attribute "shape", scales, sh0 (with the opacity
    /// logit as a fourth channel) and shN quantised linearly over mins..maxs, no codebooks, and
    /// the SH band count given only by the width of shN's centroids image.
    int version = 2;
    std::size_t count = 0;
    std::array<double, 3> means_mins{}, means_maxs{};
    std::array<std::string, 2> means_files;    // low bytes, high bytes
    std::vector<float> scales_codebook;        // 256 log scales
    std::string scales_file;
    std::string quats_file;
    std::vector<float> sh0_codebook;           // 256 SH degree-0 values
    std::string sh0_file;
    int sh_bands = 0;                          // 0: no shN
    std::size_t palette_count = 0;
    std::vector<float> shn_codebook;           // 256 SH values
    std::array<std::string, 2> shn_files;      // centroids, labels
    // Version 1 only: the linear ranges that replace the codebooks.
    std::array<double, 3> scales_mins{}, scales_maxs{};  // log scales
    std::array<double, 4> sh0_mins{}, sh0_maxs{};        // SH degree 0 (RGB), opacity logit (A)
    double shn_min = 0, shn_max = 0;                     // every SH-rest value
    bool has_shn = false;                                // shN present (version 1: bands unknown)
};

/// Parses meta.json text. `where` names it in errors ("scene.sog/meta.json"). A meta.json without
/// "version" is read as version 1 (count from "means.shape[0]", linear ranges instead of
/// codebooks, its fields checked as version 2's are). Throws IOError for invalid JSON, a version
/// other than 1 (absent) or 2, a missing or mistyped field, a count above
/// `max_gaussians`, codebooks that are not 256 finite numbers, non-finite or reversed means
/// bounds, shN bands outside 1..3 or a palette count outside 1..65536, and image names that are
/// not plain file names.
Meta parse_meta(const std::string& text, const std::string& where, std::size_t max_gaussians);

/// meta.json text for `meta` (splat-transform's layout, numbers to float32 round-trip precision).
std::string format_meta(const Meta& meta);

}  // namespace avsplat::sog
