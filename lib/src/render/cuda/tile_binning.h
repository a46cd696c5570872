// Tile binning on the GPU: the kernel bodies that turn visible splats into (tile, depth, index)
// keys and, after the radix sort, into per-tile ranges. AVSPLAT_HD, so the CPU tests run the same
// code (tests/cpp/test_render_cuda.cpp). Header-only, no STL.
#pragma once

#include "avsplat/common/hostdevice.h"
#include "render/shared/splat_record.h"
#include "render/shared/tiling.h"

#include <stdint.h>

namespace avsplat::gpu {

using blend::SplatRecord;

/// Key-emission kernel body for a visible Gaussian `index`: writes one (tile, depth) key and
/// the index for every tile its box meets, in row-major tile order, to keys[0..n) and
/// values[0..n) where n is project_record's count. Gaussians write their runs in index order
/// (offsets from a scan of the counts), so the stable radix sort leaves equal keys in index
/// order: the (depth, index) order of tiling.h.
template <class T>
AVSPLAT_HD void write_tile_keys(const SplatRecord<T>& rec, uint32_t index, int tiles_x,
                                uint64_t* keys, uint32_t* values) {
    const tiling::TileRect r = tiling::tile_rect(rec.x_min, rec.x_max, rec.y_min, rec.y_max);
    const float depth = float(rec.depth);  // the float32 sort depth of tiling.h, in both precisions
    uint64_t k = 0;
    for (int ty = r.y0; ty < r.y1; ++ty)
        for (int tx = r.x0; tx < r.x1; ++tx, ++k) {
            keys[k] = tiling::tile_depth_key(uint32_t(ty) * uint32_t(tiles_x) + uint32_t(tx), depth);
            values[k] = index;
        }
}

/// The tile id stored in a tile_depth_key.
AVSPLAT_HD uint32_t key_tile(uint64_t key) { return uint32_t(key >> 32); }

/// Tile-range kernel body for position i of the n sorted keys: where a run of equal tile ids
/// starts, sets starts[tile] = i; where it ends, ends[tile] = i + 1. Tiles without instances
/// keep the value the arrays were cleared to (0, an empty range).
AVSPLAT_HD void mark_tile_range(const uint64_t* sorted_keys, uint32_t i, uint32_t n,
                                uint32_t* starts, uint32_t* ends) {
    const uint32_t tile = key_tile(sorted_keys[i]);
    if (i == 0 || key_tile(sorted_keys[i - 1]) != tile) starts[tile] = i;
    if (i + 1 == n || key_tile(sorted_keys[i + 1]) != tile) ends[tile] = i + 1;
}

}  // namespace avsplat::gpu
