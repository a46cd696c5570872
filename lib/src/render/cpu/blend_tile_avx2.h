// The AVX2 tile kernel of the CPU renderer (float32): blend_tile.h's compositing with 8 pixels
// per instruction, written with intrinsics. Same operations in the same order as the portable
// kernel (blend.h's arithmetic, no FMA), so both give the same image bit for bit; render_cpu.cpp
// picks one per frame (cpu_kernel.h).
#pragma once

#include "render/cpu/tile_state.h"

#include <cstddef>
#include <cstdint>

namespace avsplat::detail::cpu {

/// Whether this build contains the AVX2 kernel (GCC or Clang on x86-64) and the CPU runs it.
bool avx2_kernel_available();

/// blend_tile<kContrib>(...) of blend_tile.h for float, kContrib = (contrib != nullptr): the
/// same arguments, the same results. Only call it where avx2_kernel_available().
std::uint64_t blend_tile_avx2(int tx, int ty, const std::uint32_t* list, std::size_t n_list,
                              const SplatRecord<float>* splats, const BlendParams<float>& p,
                              RenderResult& out, Contribution<float>* contrib);

}  // namespace avsplat::detail::cpu
