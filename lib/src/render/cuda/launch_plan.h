// Host-side orchestration of a CUDA frame that does not need a GPU: launch geometry, the bits
// the radix sort must look at, the limits on buffer sizes, and the wording of validation
// errors. render_cuda.cu uses these to size buffers and launch kernels; the CPU tests call the
// same functions and check them against tiling.h and the CPU renderer.
//
// Plain C++17, header-only, no CUDA headers.
#pragma once

#include "avsplat/core/error.h"
#include "render/shared/tiling.h"
#include "render/cuda/kernel_bodies.h"

#include <cstddef>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>

namespace avsplat::gpu {

/// Threads of a compositing block: one per pixel of a tile. Also the number of splats staged in
/// shared memory per batch, so that every thread loads exactly one.
constexpr int kBlockPixels = tiling::kTileSize * tiling::kTileSize;

/// Threads per block of the one-thread-per-item kernels (projection, keys, ranges, checks).
constexpr int kThreadsPerBlock = 256;

/// Largest number of (splat, tile) instances in one frame: instance positions are 32-bit in
/// the tile ranges, and the sort is given an int count. At 24 bytes of keys and values per
/// instance (double-buffered) the limit is far beyond the memory of current GPUs anyway.
constexpr std::uint64_t kMaxTileInstances = std::uint64_t(std::numeric_limits<std::int32_t>::max());

/// Largest grid y dimension of a CUDA launch (the compositing grid is tiles_x x tiles_y).
constexpr int kMaxGridY = 65535;

/// The shape of a frame's work.
struct FramePlan {
    int width = 0, height = 0;     ///< image size, pixels
    int tiles_x = 0, tiles_y = 0;  ///< tiles along x and y (tiling::tiles_along)
    std::uint32_t tiles = 0;       ///< tiles_x * tiles_y; tile ids are 0..tiles-1
    std::size_t pixels = 0;        ///< width * height
    /// The radix sort looks at key bits [0, sort_end_bit): the 32 depth bits and just enough
    /// bits for the largest tile id, since higher bits are zero in every key.
    int sort_end_bit = 32;
};

/// Number of bits needed to write v (0 for v = 0).
inline int bit_width(std::uint32_t v) {
    int bits = 0;
    for (; v != 0; v >>= 1) ++bits;
    return bits;
}

/// The plan of a width x height frame. Throws std::invalid_argument for a size that is not
/// positive or whose tile grid does not fit a CUDA launch or 32-bit tile ids.
inline FramePlan plan_frame(int width, int height) {
    if (width <= 0 || height <= 0)
        throw std::invalid_argument("CUDA renderer: image size " + std::to_string(width) + " x " +
                                    std::to_string(height) + " is not positive");
    FramePlan p;
    p.width = width;
    p.height = height;
    p.tiles_x = tiling::tiles_along(width);
    p.tiles_y = tiling::tiles_along(height);
    if (p.tiles_y > kMaxGridY)
        throw std::invalid_argument("CUDA renderer: image height " + std::to_string(height) +
                                    " needs " + std::to_string(p.tiles_y) + " tile rows; at most " +
                                    std::to_string(kMaxGridY) + " are supported");
    const std::uint64_t tiles = std::uint64_t(p.tiles_x) * std::uint64_t(p.tiles_y);
    if (tiles > std::uint64_t(std::numeric_limits<std::uint32_t>::max()))
        throw std::invalid_argument("CUDA renderer: " + std::to_string(tiles) +
                                    " tiles do not fit 32-bit tile ids");
    p.tiles = std::uint32_t(tiles);
    p.pixels = std::size_t(width) * std::size_t(height);
    p.sort_end_bit = 32 + bit_width(p.tiles - 1);
    return p;
}

/// Blocks of kThreadsPerBlock threads covering n items (n may exceed 2^32; the grid's x limit,
/// 2^31 - 1 blocks, is far above 2^32 / 256).
inline unsigned grid_blocks(std::uint64_t n) {
    return unsigned((n + kThreadsPerBlock - 1) / kThreadsPerBlock);
}

/// Throws avsplat::DeviceError when a frame has more tile instances than one sort handles.
inline void check_tile_instances(std::uint64_t instances) {
    if (instances > kMaxTileInstances)
        throw DeviceError("CUDA renderer: the frame has " + std::to_string(instances) +
                          " (splat, tile) instances; at most " + std::to_string(kMaxTileInstances) +
                          " fit one sort (lower the resolution or split the cloud)");
}

/// SH floats per Gaussian for SH degree d: 3 (d + 1)^2.
inline std::uint64_t sh_floats(int sh_degree) {
    return 3 * std::uint64_t(sh_degree + 1) * std::uint64_t(sh_degree + 1);
}

/// Element counts of the device buffers of one frame; render_cuda.cu allocates exactly these
/// (the keys and values, one per (splat, tile) instance, once the instances are counted).
struct FrameSizes {
    std::uint64_t gaussians = 0;  ///< splat records, tile counts, key offsets: one each per Gaussian
    std::uint64_t input_floats = 0;  ///< floats of the uploaded arrays: means 3, scales 3, rotations 4, opacity 1, SH
    std::uint64_t tiles = 0;      ///< tile range starts, and ends: one each per tile
    std::uint64_t pixels = 0;     ///< alpha, depth, contributors; the colour image holds 3 x pixels

    /// Device bytes of the frame with `instances` (splat, tile) pairs (keys and values, both
    /// double-buffered for the sort) and splat records of `record_bytes`, plus the uploaded
    /// inputs when `with_inputs`. CUB's scratch space is not counted. For messages.
    std::uint64_t bytes(std::uint64_t instances, std::size_t record_bytes, bool with_inputs) const {
        std::uint64_t b = gaussians * (record_bytes + 2 * sizeof(std::uint64_t));
        if (with_inputs) b += input_floats * sizeof(float);
        b += 2 * instances * (sizeof(std::uint64_t) + sizeof(std::uint32_t));
        b += 2 * tiles * sizeof(std::uint32_t);
        b += pixels * (5 * sizeof(float) + sizeof(std::int32_t));
        return b;
    }
};

/// The buffers of a frame of n Gaussians of SH degree `sh_degree` with plan `p`.
inline FrameSizes frame_sizes(const FramePlan& p, std::uint64_t n, int sh_degree) {
    FrameSizes s;
    s.gaussians = n;
    s.input_floats = n * (3 + 3 + 4 + 1 + sh_floats(sh_degree));
    s.tiles = p.tiles;
    s.pixels = p.pixels;
    return s;
}

/// The name of a validated field in messages.
inline const char* field_name(Field f) { return gaussian_field_name(f); }

/// What is wrong, in the words of avsplat::validate's messages.
inline const char* invalid_text(Invalid r) {
    switch (r) {
        case Invalid::None: return "valid";
        case Invalid::NonFinite: return "NaN or Inf";
        case Invalid::NegativeScale: return "negative scale";
        case Invalid::ZeroRotation: return "zero-norm quaternion";
        case Invalid::OpacityRange: return "opacity outside [0, 1]";
    }
    return "?";
}

/// "DeviceGaussians.<field>[<index>]: <what>", the message of an invalid device Gaussian.
inline std::string invalid_message(std::uint64_t index, Field f, Invalid r) {
    return std::string("DeviceGaussians.") + field_name(f) + "[" + std::to_string(index) + "]: " +
           invalid_text(r);
}

}  // namespace avsplat::gpu
