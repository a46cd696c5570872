// The per-Gaussian record both renderers blend from, and the compositing constants of a frame:
// one definition for the CPU renderer (render_cpu.cpp) and the CUDA renderer (kernel_bodies.h).
//
// Header-only, no Eigen, no STL, no exceptions; nvcc parses it.
#pragma once

namespace avsplat::blend {

/// What compositing reads of one visible Gaussian, written by preprocess::project_record
/// (project_and_shade.h); a culled Gaussian's record is never read. Packed (56 bytes in float):
/// the GPU stages these in shared memory. The CPU renderer wraps it in a cache-line aligned
/// type, because its tiles visit records in depth order, not in memory order.
template <class T>
struct SplatRecord {
    T mean_x, mean_y;                ///< projected mean, pixels
    T conic_a, conic_b, conic_c;     ///< inverse 2D covariance (a, b, c), see blend.h
    T opacity;                       ///< in [0, 1]
    T rgb[3];                        ///< max(SH + 0.5, 0)
    T depth;                         ///< camera-space z of the mean
    int x_min, x_max, y_min, y_max;  ///< inclusive pixel box, clipped to the image
};

/// The compositing constants of a frame, RenderOptions' values rounded to T.
template <class T>
struct BlendParams {
    T alpha_threshold;
    T transmittance_stop;
    T background[3];
};

}  // namespace avsplat::blend
