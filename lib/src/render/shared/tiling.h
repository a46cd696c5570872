// Tile binning shared by the CPU and CUDA renderers: which 16 x 16 pixel tiles a splat touches
// and the sort keys that order splats within a tile.
//
// The image is cut into tiles of kTileSize x kTileSize pixels, tile (tx, ty) holding pixels
// [16 tx, 16 tx + 16) x [16 ty, 16 ty + 16), numbered ty * tiles_x + tx. A splat is listed in
// every tile that its clipped pixel box (projection::Splat::x_min..x_max, y_min..y_max) meets, so
// a tile's list holds exactly the splats that may touch one of its pixels.
//
// Within a tile, splats are composited by increasing view depth, ties broken by increasing
// Gaussian index, so the image is deterministic. The depth used for ordering is the float32
// value of the camera-space z in both precisions, so the float and double paths order alike.
// Keys: the CUDA path sorts one global array of tile_depth_key(tile, depth) with a stable sort
// over Gaussians listed in index order; the CPU path sorts each tile's depth_index_key(depth,
// index). Both give the same order.
//
// Header-only, no STL, AVSPLAT_HD.
#pragma once

#include "avsplat/common/hostdevice.h"
#include "common/order_key.h"

#include <stdint.h>
#include <string.h>

namespace avsplat::tiling {

/// Tile edge in pixels.
constexpr int kTileSize = 16;

/// Number of tiles covering `pixels` pixels along one axis.
AVSPLAT_HD int tiles_along(int pixels) { return (pixels + kTileSize - 1) / kTileSize; }

/// A half-open rectangle of tiles [x0, x1) x [y0, y1).
struct TileRect {
    int x0, y0, x1, y1;
};

/// The tiles met by the inclusive pixel box [x_min, x_max] x [y_min, y_max] (non-negative
/// coordinates, as a clipped projection::Splat box).
AVSPLAT_HD TileRect tile_rect(int x_min, int x_max, int y_min, int y_max) {
    TileRect r;
    r.x0 = x_min / kTileSize;
    r.x1 = x_max / kTileSize + 1;
    r.y0 = y_min / kTileSize;
    r.y1 = y_max / kTileSize + 1;
    return r;
}

/// Number of tiles in a rectangle (0 when it is empty).
AVSPLAT_HD int tile_count(const TileRect& r) {
    return (r.x1 > r.x0 && r.y1 > r.y0) ? (r.x1 - r.x0) * (r.y1 - r.y0) : 0;
}

/// An unsigned integer that orders like the float `depth` (common/order_key.h).
AVSPLAT_HD uint32_t depth_bits(float depth) { return float_order_key(depth); }

/// Key of a splat instance in the global sort: tile id in the high 32 bits, depth below.
AVSPLAT_HD uint64_t tile_depth_key(uint32_t tile, float depth) {
    return (uint64_t(tile) << 32) | uint64_t(depth_bits(depth));
}

/// Key of a splat within one tile's list: depth in the high 32 bits, Gaussian index below, so
/// that equal depths order by index.
AVSPLAT_HD uint64_t depth_index_key(float depth, uint32_t index) {
    return (uint64_t(depth_bits(depth)) << 32) | uint64_t(index);
}

/// The Gaussian index stored in a depth_index_key.
AVSPLAT_HD uint32_t key_index(uint64_t key) { return uint32_t(key & 0xffffffffu); }

}  // namespace avsplat::tiling
