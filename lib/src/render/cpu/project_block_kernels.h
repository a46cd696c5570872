// The vector kernels of the projection stage (project_splats.h): blocks of 8 Gaussians across
// vector lanes, the body in project_block.h, compiled for AVX2 (project_block_avx2.cpp) and
// AVX-512 (project_block_avx512.cpp). Availability is the tile kernels' (blend_tile_avx2.h,
// blend_tile_avx512.h): one AVSPLAT_CPU_KERNEL choice picks both.
#pragma once

#include "avsplat/core/gaussians.h"
#include "render/cpu/tile_state.h"
#include "render/shared/project_and_shade.h"

#include <cstdint>

namespace avsplat::detail::cpu {

/// Gaussians per block.
constexpr int kProjectLanes = 8;

/// project_one (project_splats.h) for Gaussians [begin, begin + 8 * blocks) of `cloud`, 8 at a
/// time. Only call it where avx2_kernel_available().
void project_blocks_avx2(const preprocess::ViewParams<float>& view, const GaussianCloud& cloud, float alpha_threshold,
                         std::int64_t begin, std::int64_t blocks, SplatRecord<float>* splats, std::uint64_t* keys);

/// The same with AVX-512 double lanes. Only call it where avx512_kernel_available().
void project_blocks_avx512(const preprocess::ViewParams<float>& view, const GaussianCloud& cloud,
                           float alpha_threshold, std::int64_t begin, std::int64_t blocks,
                           SplatRecord<float>* splats, std::uint64_t* keys);

/// rec.power_cut = power_cutoff(rec, alpha_threshold), out of line and compiled for the baseline
/// ISA: the vector kernels call it for the rare lanes their own power_cut does not cover (a
/// quotient alpha_threshold / opacity below the smallest normal float, where log_lower_bound calls
/// std::log).
void power_cut_scalar(SplatRecord<float>& rec, float alpha_threshold);

}  // namespace avsplat::detail::cpu
