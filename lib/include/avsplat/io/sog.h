// PlayCanvas SOG ("spatially ordered Gaussians", meta.json version 2): the web format of
// splat-transform, SuperSplat and the PlayCanvas engine. Version 1 (splat-transform before 1.0: no
// "version", per-attribute "shape" and "dtype", linear mins..maxs ranges instead of codebooks) is
// read too. A `meta.json` plus lossless WebP images,
// either bundled as a `.sog` zip archive or side by side in a folder.
//
// Per Gaussian i, texel i (row-major) of each image holds:
//   means_l.webp, means_u.webp  low and high bytes of three 16-bit values: the position, after
//                               v -> sign(v) ln(1 + |v|), spread over meta's per-axis [mins, maxs]
//   quats.webp                  the unit quaternion, smallest three: RGB the three smaller
//                               components times sqrt(2) in [-1, 1] over 0..255, A 252 + the index
//                               (w, x, y, z) of the dropped largest component (made positive)
//   scales.webp                 RGB: indices into a 256-entry codebook of log scales
//   sh0.webp                    RGB: indices into a 256-entry codebook of SH degree-0
//                               coefficients; A: opacity * 255
//   shN_labels.webp             (SH degree 1..3) RG: a 16-bit index into the SH palette
//   shN_centroids.webp          the palette: 64 entries per row, each (d+1)^2-1 texels wide, RGB
//                               of a texel the indices of coefficient j's three channels into a
//                               256-entry codebook of SH values
// Version 1 has the same images; its meta.json gives the count as "means.shape[0]", and instead of
// codebooks linear ranges: byte b of scales.webp is exp(mins[a] + (maxs[a] - mins[a]) b / 255) on
// axis a; sh0.webp's RGB the same over "sh0" mins/maxs [0..2] and A the opacity's logit over
// mins/maxs[3]; a palette byte of shN mins + (maxs - mins) b / 255 (scalar range); the SH bands
// follow from the centroids' width (192, 512, 960 texels: bands 1, 2, 3).
//
// What it keeps and loses: positions to 16 bits per axis (after the log transform), rotations to
// 8 bits per smaller component, scales and colours to 256 shared levels each, opacity to 8 bits,
// and the higher SH bands to a palette of at most 65536 vectors (k-means) with 256 shared levels.
// Confidence and extra channels are dropped. Gaussians are written in Morton order of their
// positions (as splat-transform does), so reading returns them in that order, not the input's.
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>

namespace avsplat {

/// How `write_sog` encodes. Defaults match splat-transform 3.7.0's where it has one.
struct SogWriteOptions {
    /// Lloyd iterations of the SH palette k-means (splat-transform: 10).
    int iterations = 10;
    /// SH palette entries; 0 chooses splat-transform's rule
    /// min(64, 2^floor(log2(N / 1024))) * 1024, i.e. 1024 per 1024 Gaussians in powers of two
    /// up to 65536. At most 65536 (16-bit labels). With fewer Gaussians than entries every
    /// Gaussian is its own entry.
    int palette_size = 0;
    /// Seeds the palette's initial entries and the re-seeding of empty clusters. The output
    /// depends only on the cloud, these options and the seed: not on the thread count.
    std::uint64_t seed = 0;
    /// How each SH-rest vector finds its palette entry. false (default): an exhaustive search
    /// for small problems and, when one pass would take more than 3e10 multiply-adds (above
    /// 32,768 SH-3 Gaussians with the default palette size), a grouped search: the entries
    /// form about sqrt(palette) groups and each vector is compared with the entries of the 8
    /// groups nearest to it (about 1/20 of the work at 65,536 entries; the SH-rest error rose
    /// 0.14 % at 300,000 and 0.65 % at 50,000 trained-like Gaussians, 4.1 % in the worst case
    /// measured, i.i.d. noise with barely more Gaussians than entries:
    /// docs/benchmarks/sog.md). true: always exhaustive (each label the nearest entry;
    /// minutes from a few 10^5 SH-3 Gaussians on).
    bool exact_palette = false;
    /// true (default): Gaussians are stored in Morton order of their positions, as
    /// splat-transform stores them. false: in the cloud's order (a LOD set's chunks, whose tree
    /// nodes are ranges of rows).
    bool morton_order = true;
};

/// Limits `read_sog` enforces before it allocates, against lying meta.json files and WebP bombs.
struct SogReadLimits {
    /// Largest `count` accepted (and so the largest cloud allocated): 2^26.
    std::size_t max_gaussians = std::size_t(1) << 26;
};

/// The files of one SOG: name -> bytes ("meta.json", "means_l.webp", ...).
using SogFiles = std::map<std::string, std::string>;

/// Reads a SOG: `path` is a `.sog` zip archive, a meta.json file (images resolved beside it) or a
/// folder holding meta.json. Returns N Gaussians of SH degree 0..3 (shN's bands), in file order:
/// means decoded from the 16-bit log-space values, scales exp(codebook), rotations unit
/// (w, x, y, z), opacity A / 255, SH from the codebooks (version 1: from the linear ranges, as
/// splat-transform 3.7 decodes them). Throws avsplat::IOError naming the file
/// and the field: not a SOG, meta.json not version 1 or 2 or malformed (missing or non-numeric fields,
/// codebooks not 256 finite numbers, a count above `limits`), an image missing, not a WebP or
/// smaller than the count, a quaternion tag outside 252..255, a palette label outside the palette,
/// or more than 2^20 Gaussians whose float32 arrays would take over 65536 times the bytes of the
/// SOG's images (nearly constant images that declare gigabytes).
GaussianCloud read_sog(const std::string& path, const SogReadLimits& limits = {});

/// Whether `path` holds a SOG, by content: a folder with meta.json, a zip archive with a
/// meta.json entry, or a JSON file with SOG's "means" and "quats" objects. Never throws; false
/// when the path cannot be read.
bool is_sog(const std::string& path);

/// Writes `cloud` (validated first: std::invalid_argument) as a SOG: a `.sog` path gives a zip
/// archive (entries stored, WebP is compressed already), a path ending in `.json` gives that
/// meta.json with the images beside it, any other path a folder (created when missing) holding
/// meta.json and the images. Every file goes through an AtomicFile; in the folder form meta.json
/// is written last. Throws avsplat::IOError naming the file that cannot be written, and
/// std::invalid_argument for options out of range or more than 16383 x 16383 Gaussians (WebP's
/// largest image); avsplat::IOError, before any file is written, for a cloud read_sog would refuse
/// (over 2^20 Gaussians so alike that the images expand over 65536 times).
void write_sog(const std::string& path, const GaussianCloud& cloud, const SogWriteOptions& options = {});

/// The files `write_sog` writes, in memory (no zip): meta.json and the WebP images.
SogFiles encode_sog(const GaussianCloud& cloud, const SogWriteOptions& options = {});

/// Decodes the files of one SOG held in memory; `name` stands for the source in error messages
/// ("<name>/meta.json: ..."). Image names in meta.json must be plain file names (no '/', no "..").
GaussianCloud decode_sog(const SogFiles& files, const std::string& name, const SogReadLimits& limits = {});

/// Decodes a `.sog` zip archive held in memory (`size` bytes at `data`), as read_sog does a file.
GaussianCloud parse_sog(const void* data, std::size_t size, const std::string& name,
                        const SogReadLimits& limits = {});

}  // namespace avsplat
