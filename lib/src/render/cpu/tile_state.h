// What the CPU renderer's tile kernels share: the splat record they read, the running state of a
// tile's 256 pixels, the per-Gaussian contribution accumulators, and the start and the output
// of a tile. The kernels are blend_tile.h (portable C++, float and double) and
// blend_tile_avx2.cpp (AVX2 intrinsics, float); render_cpu.cpp picks one (cpu_kernel.h).
#pragma once

#include "avsplat/render/render.h"
#include "render/shared/blend.h"
#include "render/shared/splat_record.h"
#include "render/shared/tiling.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

namespace avsplat::detail::cpu {

constexpr int kTile = tiling::kTileSize;
constexpr int kTilePixels = kTile * kTile;
constexpr int kChunk = 8;  // lanes per vector step: one AVX register, two SSE registers

using blend::BlendParams;

/// The shared splat record (splat_record.h) plus `power_cut`, cache-line aligned (one line in
/// float, two in double). The records a frame blends are stored in compositing (depth) order,
/// so that a tile's list walks them forwards through memory.
template <class T>
struct alignas(64) SplatRecord : blend::SplatRecord<T> {
    /// No pixel where the splat's power (blend.h) is below this can reach alpha_threshold, so a
    /// kernel may skip pixels below it without changing any result (power_cutoff). Written
    /// for float records only, which the AVX2 kernel reads; the portable kernel ignores it.
    T power_cut;
};

/// A lower bound of log(x) for x > 0, within 2e-3 of it, without a libm call: with
/// x = m 2^e, m in [1, 2) and t = (m - 1) / (m + 1) in [0, 1/3), log m = 2 atanh t =
/// 2 (t + t^3 / 3 + t^5 / 5 + ...) >= 2 t + (2/3) t^3, which falls short by at most
/// 2 (1/3)^5 / 5 / (1 - 1/9) < 2e-3 (the terms left out); e log 2 adds a rounding error below
/// 1e-5 for the normal floats. Subnormal x goes to std::log.
inline float log_lower_bound(float x) {
    if (!(x >= std::numeric_limits<float>::min())) return std::log(x);
    std::uint32_t bits;
    std::memcpy(&bits, &x, sizeof bits);
    const int e = int((bits >> 23) & 0xffu) - 127;
    bits = (bits & 0x007fffffu) | 0x3f800000u;  // the mantissa as a float in [1, 2)
    float m;
    std::memcpy(&m, &bits, sizeof m);
    const float t = (m - 1.0f) / (m + 1.0f);
    return float(e) * 0.693147180559945f + (2.0f * t + (2.0f / 3.0f) * t * t * t);
}
inline double log_lower_bound(double x) { return std::log(x); }

/// The power below which a splat of `opacity` cannot reach `alpha_threshold`: alpha = opacity
/// exp(power) >= alpha_threshold needs power >= log(alpha_threshold / opacity). The cut is a
/// lower bound of that (log_lower_bound) less a margin of 1e-3, which covers exp_nonpositive's
/// error (about 1 ulp, blend.h) and the rounding of the products and of the quotient here many
/// times over; so it is within 3e-3 of the exact value. -infinity (skip nothing) where
/// skipping would not be exact: a non-finite colour or depth (0 times it is NaN, which a
/// skipped pixel would not get) or a NaN opacity.
template <class T>
T power_cutoff(const blend::SplatRecord<T>& s, T alpha_threshold) {
    const bool finite = std::isfinite(s.rgb[0]) && std::isfinite(s.rgb[1]) && std::isfinite(s.rgb[2]) &&
                        std::isfinite(s.depth) && !std::isnan(s.opacity) && alpha_threshold > T(0);
    if (!finite) return -std::numeric_limits<T>::infinity();
    if (!(s.opacity > T(0))) return std::numeric_limits<T>::infinity();  // alpha is always 0
    return log_lower_bound(alpha_threshold / s.opacity) - T(1e-3);
}

/// Running state of the 256 pixels of a tile, one array per quantity so that a row is one
/// vector load per quantity. `done` is 1 for a saturated pixel or one outside the image.
template <class T>
struct TileState {
    alignas(64) T transmittance[kTilePixels];
    alignas(64) T red[kTilePixels];
    alignas(64) T green[kTilePixels];
    alignas(64) T blue[kTilePixels];
    alignas(64) T depth[kTilePixels];
    alignas(64) std::int32_t count[kTilePixels];
    alignas(64) std::int32_t done[kTilePixels];
};

/// The max and the sum of one splat's c(p) (render.h) over the pixels of a tile.
template <class T>
struct Contribution {
    T max = T(0);
    T sum = T(0);
};

/// The same per lane of a chunk while a splat is composited: lane-wise updates keep the pixel
/// loop vectorised; the lanes are combined in lane order at the end (combine), so the result
/// does not depend on the kernel.
template <class T>
struct LaneContribution {
    alignas(64) T max[kChunk];
    alignas(64) T sum[kChunk];

    Contribution<T> combine() const {
        Contribution<T> total;
        for (int l = 0; l < kChunk; ++l) {
            total.max = max[l] > total.max ? max[l] : total.max;
            total.sum += sum[l];
        }
        return total;
    }
};

/// The tile's pixels in [0, w) x [0, h) of the image: fresh state, the others done.
template <class T>
void tile_start(TileState<T>& st, int w, int h) {
    for (int r = 0; r < kTile; ++r) {
        for (int l = 0; l < kTile; ++l) {
            const int k = r * kTile + l;
            st.transmittance[k] = T(1);
            st.red[k] = st.green[k] = st.blue[k] = st.depth[k] = T(0);
            st.count[k] = 0;
            st.done[k] = (r < h && l < w) ? 0 : 1;
        }
    }
}

/// The final float32 values (blend::finish_pixel) of the 16 pixels of a tile row.
struct FinishedRow {
    alignas(64) float red[kTile];
    alignas(64) float green[kTile];
    alignas(64) float blue[kTile];
    alignas(64) float alpha[kTile];
    alignas(64) float depth[kTile];
};

/// blend::finish_pixel for the 16 pixels of tile row r. The vector kernels have their own copy
/// of this with intrinsics (the same operations, so the same bits): GCC keeps a branch for the
/// select here, which mispredicts at the image's edges of coverage.
template <class T>
void finish_row(const TileState<T>& st, int r, const BlendParams<T>& p, FinishedRow& row) {
    for (int l = 0; l < kTile; ++l) {
        const int k = r * kTile + l;
        const T sum[3] = {st.red[k], st.green[k], st.blue[k]};
        T rgb[3], alpha, depth;
        blend::finish_pixel(st.transmittance[k], sum, st.depth[k], p.background, rgb, alpha, depth);
        row.red[l] = float(rgb[0]);
        row.green[l] = float(rgb[1]);
        row.blue[l] = float(rgb[2]);
        row.alpha[l] = float(alpha);
        row.depth[l] = float(depth);
    }
}

/// Copies the first w pixels of a finished tile row, and their contributor counts, to the
/// images at pixel (x0, y) (the colour interleaved).
inline void copy_row_out(const FinishedRow& row, const std::int32_t* count, int x0, int y, int w,
                         RenderResult& out) {
    const std::size_t pix = std::size_t(y) * std::size_t(out.width) + std::size_t(x0);
    float* const color = out.color.data() + 3 * pix;
    for (int l = 0; l < w; ++l) {
        color[3 * l] = row.red[l];
        color[3 * l + 1] = row.green[l];
        color[3 * l + 2] = row.blue[l];
    }
    std::memcpy(out.alpha.data() + pix, row.alpha, std::size_t(w) * sizeof(float));
    std::memcpy(out.depth.data() + pix, row.depth, std::size_t(w) * sizeof(float));
    std::memcpy(out.contributors.data() + pix, count, std::size_t(w) * sizeof(std::int32_t));
}

/// Writes the final values (blend::finish_pixel) of the tile at pixel (x0, y0), w x h pixels.
template <class T>
void tile_write(const TileState<T>& st, int x0, int y0, int w, int h, const BlendParams<T>& p,
                RenderResult& out) {
    for (int r = 0; r < h; ++r) {
        FinishedRow row;
        finish_row(st, r, p, row);
        copy_row_out(row, st.count + r * kTile, x0, y0 + r, w, out);
    }
}

}  // namespace avsplat::detail::cpu
