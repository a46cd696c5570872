// Which tile kernel the CPU renderer runs for a float32 frame: the AVX-512 one where the CPU has
// AVX-512F, else the AVX2 one where it has AVX2, else the portable one (blend_tile.h), unless
// the environment variable AVSPLAT_CPU_KERNEL says otherwise. All give the same image bit for
// bit; the variable exists so that tests and benchmarks can run each on the same machine.
// Float64 frames always use the portable kernel (the reference path).
#pragma once

namespace avsplat::detail::cpu {

enum class CpuKernel { Portable, Avx2, Avx512 };

/// The kernel for the next float32 frame, from AVSPLAT_CPU_KERNEL, read at each call:
/// unset, empty or "auto": Avx512 where avx512_kernel_available(), else Avx2 where
/// avx2_kernel_available(), else Portable; "scalar": Portable; "avx2": Avx2; "avx512": Avx512.
/// Throws std::invalid_argument for any other value, and for "avx2" or "avx512" where this
/// build or this CPU has no such kernel.
CpuKernel cpu_kernel();

}  // namespace avsplat::detail::cpu
