#include "render/cpu/cpu_kernel.h"

#include "render/cpu/blend_tile_avx2.h"
#include "render/cpu/blend_tile_avx512.h"

#include <cstdlib>
#include <stdexcept>
#include <string>

namespace avsplat::detail::cpu {

CpuKernel cpu_kernel() {
    const char* env = std::getenv("AVSPLAT_CPU_KERNEL");
    const std::string choice = env ? env : "";
    if (choice.empty() || choice == "auto") {
        if (avx512_kernel_available()) return CpuKernel::Avx512;
        return avx2_kernel_available() ? CpuKernel::Avx2 : CpuKernel::Portable;
    }
    if (choice == "scalar") return CpuKernel::Portable;
    if (choice == "avx2") {
        if (!avx2_kernel_available())
            throw std::invalid_argument("AVSPLAT_CPU_KERNEL=avx2: this build or this CPU has no AVX2 kernel");
        return CpuKernel::Avx2;
    }
    if (choice == "avx512") {
        if (!avx512_kernel_available())
            throw std::invalid_argument("AVSPLAT_CPU_KERNEL=avx512: this build or this CPU has no AVX-512 kernel");
        return CpuKernel::Avx512;
    }
    throw std::invalid_argument("AVSPLAT_CPU_KERNEL: unknown value '" + choice +
                                "' (expected auto, scalar, avx2 or avx512)");
}

}  // namespace avsplat::detail::cpu
