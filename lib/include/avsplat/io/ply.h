// 3DGS PLY reading and writing (the INRIA layout every splat viewer reads).
//
// Vertex properties: x y z nx ny nz f_dc_0..2 f_rest_0..(3*(K-1)-1) opacity scale_0..2 rot_0..3.
// On disk opacity is a logit, scale is log(scale), rot is (w, x, y, z) and f_rest is
// channel-major (all R coefficients of bands 1.., then G, then B: f_rest_{c*(K-1)+j} is
// coefficient j+1 of channel c); in memory GaussianCloud holds opacity in [0, 1], linear scales
// and SH as N x K x 3.
//
// Reading accepts binary little endian, binary big endian and ASCII; properties in any order;
// float, double and the integer PLY types (char uchar short ushort int uint, their int8..uint32
// names, float32 / float64); SH degree 0..3 inferred from the number of f_rest properties (0, 9,
// 24 or 45); any other vertex property is kept: "confidence" becomes GaussianCloud::confidence,
// everything else a named extra channel in header order; normals are dropped. Comments and
// obj_info lines are allowed. Elements other than "vertex" are skipped, before it (lists
// included) or after it. Values are converted to float32 and not validated (a NaN in the file is
// a NaN in the cloud): call validate() or sanitize() before relying on them.
//
// Writing produces binary little endian with SH of the degree stored (nothing for absent bands),
// nx ny nz as zeros, then "confidence" (when present) and the extra channels as float properties.
//
// Round trip write -> read: means, rotations, SH, confidence and extras come back bit-exact.
// Opacity and scale go through a float32 logit / log on disk, computed and decoded in double and
// rounded once; they come back bit-exact for scales in [1/e, e] and opacities in [0.25, 1], and
// within 8 ulp for scales in [1e-6, 1e3] and opacities in [1e-6, 1]. (float32 on disk has fewer
// log values than there are float32 scales below 1/e, so no float32 encoding can do better.)
//
// Every problem with a file throws avsplat::IOError naming the file and what is wrong (bad
// header, missing property, truncated data, counts that do not match the file). No allocation is
// sized by a header value before it is checked against the file size.
#pragma once

#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <memory>
#include <string>

namespace avsplat {

/// Reads a 3DGS PLY file into a GaussianCloud of N Gaussians (N = the vertex count). A PlayCanvas
/// compressed PLY (a vertex element with packed_position) is recognised by its content and read
/// with read_compressed_ply (io/compressed_ply.h).
///
/// Required vertex properties: x y z f_dc_0..2 opacity scale_0..2 rot_0..3. Throws IOError
/// (message "<path>: <problem>") when the file cannot be opened, is not PLY, has a malformed
/// header, an unknown format, a vertex list property, a missing required property, an f_rest
/// count other than 0, 9, 24 or 45, an ASCII token that is not a number of the property's type,
/// an ASCII row with too few or too many values, or a vertex count that does not match the data
/// (too little data; or, when the size of everything after the vertices is known, too much).
/// A file of another Gaussian format is refused with a message naming that format.
GaussianCloud read_ply(const std::string& path);

/// Writes `cloud` to `path` (replacing the file) as a binary little-endian 3DGS PLY file.
///
/// Calls validate(cloud) first, so no NaN, negative scale or zero quaternion is written silently:
/// std::invalid_argument names the field and the first bad index. Extra channel names must be
/// single PLY tokens (no spaces or control characters), unique, and not a 3DGS property name
/// (x, nx, f_dc_0, f_rest_3, opacity, confidence, ...), else std::invalid_argument. Opacity 0 and
/// 1 are written as -Inf and +Inf logits and scale 0 as a -Inf log, which read back as 0, 1 and 0.
/// Throws IOError naming the file when it cannot be opened or written, or when its name ends in
/// the suffix of another Gaussian format (.compressed.ply, .splat, .spz, .sog): write_gaussians
/// writes the format a name says. Other names (.ply, or no Gaussian suffix) are written as PLY.
void write_ply(const std::string& path, const GaussianCloud& cloud);

/// The bytes write_ply would write for `cloud` (same checks and exceptions, no file): for a
/// scene sent elsewhere than a file (the web viewer's pages). Holds the whole file in memory.
std::string ply_bytes(const GaussianCloud& cloud);

/// Writes a 3DGS PLY file whose Gaussians arrive in parts (the blocks of a FusionStream, say),
/// so that the whole cloud is never held in memory. The file is byte for byte what write_ply
/// writes for the parts concatenated, and it replaces `path` only at commit(), atomically (as
/// write_ply; destroying the writer without commit() leaves `path` as it was). The encoded rows
/// wait in an unlinked scratch file beside `path` (the same file system, so plan for about twice
/// the output's size there) until commit() writes the header, whose count must come first.
///
///     GaussianPlyWriter out("fused.ply");
///     for (const GaussianCloud& part : parts) out.append(part);
///     out.commit();
class GaussianPlyWriter {
public:
    /// Throws IOError naming `path` when its folder cannot be written.
    explicit GaussianPlyWriter(const std::string& path);
    ~GaussianPlyWriter();
    GaussianPlyWriter(const GaussianPlyWriter&) = delete;
    GaussianPlyWriter& operator=(const GaussianPlyWriter&) = delete;

    /// Appends the Gaussians of `part`, checked as write_ply checks a cloud (std::invalid_argument).
    /// The first part fixes the SH degree, confidence and extra channels; a later part that
    /// differs throws std::invalid_argument. Throws OutputError when the disk is full.
    void append(const GaussianCloud& part);
    /// Writes the header and the rows and renames the file into place (IOError on failure; with
    /// no part appended, an empty degree-0 cloud). Call once. A commit that fails aborts.
    void commit();
    /// Removes the temporary file and the scratch rows now, leaving `path` as it was (the
    /// destructor does the same); append() and commit() then throw std::logic_error.
    void abort() noexcept;
    /// Gaussians appended so far.
    std::size_t size() const noexcept { return size_; }
    /// The destination, as given.
    const std::string& path() const noexcept { return path_; }

private:
    void write_out();
    struct State;
    std::string path_;
    std::unique_ptr<State> state_;
    std::size_t size_ = 0;
    bool committed_ = false;
};

}  // namespace avsplat
