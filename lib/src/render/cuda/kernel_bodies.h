// The per-thread work of the CUDA renderer: one function per kernel body, AVSPLAT_HD, so that
// the kernels in render_cuda.cu are thin loops around them and the CPU tests call exactly the
// same functions on the host (tests/cpp/test_render_cuda.cpp runs the whole GPU pipeline this
// way, without a GPU, and holds it to the CPU renderer).
//
// Stages (kernels in render_cuda.cu): project_record (projection, culling, colour); tile binning
// on the GPU (tile_binning.h: write_tile_keys, mark_tile_range); then the per-pixel blend.
//
// The maths is the shared header-only code (projection.h, sh.h, tiling.h, blend.h). What this
// file adds is the glue around it, written to perform the same operations in the same order as
// the CPU renderer (render_cpu.cpp), so that with IEEE arithmetic on both sides (the CUDA sources
// are compiled with --fmad=false, see lib/CMakeLists.txt) both back ends produce the same bits:
//   - per-Gaussian projection and colour: project_and_shade.h, the very function the CPU calls;
//   - a splat is blended only at pixels whose centre lies in its clipped k-sigma box;
//   - within a tile, splats are visited by (float32 depth, Gaussian index).
//
// Header-only, no Eigen, no STL, no exceptions.
#pragma once

#include "render/shared/blend.h"
#include "render/shared/splat_record.h"
#include "avsplat/common/hostdevice.h"
#include "core/gaussian_validity.h"
#include "render/shared/projection.h"
#include "render/shared/tiling.h"
#include "render/shared/project_and_shade.h"
#include "render/cuda/tile_binning.h"

#include <math.h>
#include <stdint.h>

namespace avsplat::gpu {

/// The per-frame view parameters of the projection kernel (project_and_shade.h), built on the host
/// (kernel_params.h) and passed to the kernel by value.
template <class T>
using ViewParams = preprocess::ViewParams<T>;

/// The splat record and the compositing constants, the CPU renderer's own (splat_record.h).
using blend::BlendParams;
using blend::SplatRecord;

/// Projection kernel body for Gaussian i: preprocess::project_record, the CPU renderer's own
/// per-Gaussian code, with this file's SplatRecord. Returns the number of tiles the splat's box
/// meets, 0 when it is culled (then `rec` must not be read).
using preprocess::project_record;

/// Running state of one pixel during compositing.
template <class T>
struct PixelState {
    T transmittance;
    T rgb[3];
    T depth;              ///< sum of weight x depth
    int32_t contributors; ///< splats blended
    uint32_t evaluated;   ///< splats looked at (in the box, pixel not yet saturated)
    bool done;            ///< saturated, or outside the image
};

/// A pixel before its first splat; `inside` is false for the threads of a border tile that
/// have no pixel (they are done from the start).
template <class T>
AVSPLAT_HD PixelState<T> pixel_start(bool inside) {
    PixelState<T> p;
    p.transmittance = T(1);
    p.rgb[0] = p.rgb[1] = p.rgb[2] = T(0);
    p.depth = T(0);
    p.contributors = 0;
    p.evaluated = 0;
    p.done = !inside;
    return p;
}

/// Compositing kernel body: blends splat `s` into pixel (x, y), whose centre is (px, py) =
/// (x + 0.5, y + 0.5), with the rules of blend.h. A done pixel and a pixel outside the splat's
/// box are left untouched.
template <class T>
AVSPLAT_HD void composite(PixelState<T>& p, const SplatRecord<T>& s, int x, int y, T px, T py,
                          const BlendParams<T>& bp) {
    if (p.done || x < s.x_min || x > s.x_max || y < s.y_min || y > s.y_max) return;
    const T power = blend::gaussian_power(s.conic_a, s.conic_b, s.conic_c, px - s.mean_x, py - s.mean_y);
    const T alpha = blend::splat_alpha(s.opacity, power);
    const blend::BlendStep<T> step =
        blend::blend_step(alpha, p.transmittance, bp.alpha_threshold, bp.transmittance_stop);
    p.rgb[0] += step.weight * s.rgb[0];
    p.rgb[1] += step.weight * s.rgb[1];
    p.rgb[2] += step.weight * s.rgb[2];
    p.depth += step.weight * s.depth;
    p.transmittance = step.next_transmittance;
    p.contributors += step.blended ? 1 : 0;
    p.evaluated += 1;
    p.done = step.saturated;
}

/// The final float32 values of a pixel: rgb[3], alpha and expected depth (blend::finish_pixel).
template <class T>
AVSPLAT_HD void finish(const PixelState<T>& p, const BlendParams<T>& bp, float* rgb, float& alpha,
                       float& depth) {
    T out_rgb[3], out_alpha, out_depth;
    blend::finish_pixel(p.transmittance, p.rgb, p.depth, bp.background, out_rgb, out_alpha, out_depth);
    rgb[0] = float(out_rgb[0]);
    rgb[1] = float(out_rgb[1]);
    rgb[2] = float(out_rgb[2]);
    alpha = float(out_alpha);
    depth = float(out_depth);
}

/// Why Gaussian i of device arrays fails avsplat::validate, by the one per-Gaussian rule of
/// core/gaussian_validity.h. Used for inputs given as device pointers, which the host cannot
/// read cheaply.
using Invalid = GaussianDefect;
/// Fields named in the messages of `Invalid`, in the order checked.
using Field = GaussianField;
using avsplat::check_gaussian;

}  // namespace avsplat::gpu
