// The AVX2 kernel of the projection stage (project_block_kernels.h): project_block.h compiled
// for avx2 (double lanes as two 256-bit halves). Every header is included before the pragma, so that only
// project_block.h's file-local functions are compiled for AVX2 (see project_block.h).
#include "render/cpu/project_block_kernels.h"
#include "render/cpu/project_splats.h"

#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define AVSPLAT_PROJECT_AVX2 1
#include <immintrin.h>
#endif

#if AVSPLAT_PROJECT_AVX2

#pragma GCC push_options
#pragma GCC target("avx2")
#pragma GCC diagnostic ignored "-Wpsabi"  // 64-byte vector values between inline functions
#include "render/cpu/project_block.h"

namespace avsplat::detail::cpu {

void project_blocks_avx2(const preprocess::ViewParams<float>& view, const GaussianCloud& cloud, float alpha_threshold,
                         std::int64_t begin, std::int64_t blocks, SplatRecord<float>* splats, std::uint64_t* keys) {
    project_blocks(view, cloud, alpha_threshold, begin, blocks, splats, keys);
}

}  // namespace avsplat::detail::cpu

#pragma GCC pop_options

#else  // no AVX2 kernel in this build

namespace avsplat::detail::cpu {

void project_blocks_avx2(const preprocess::ViewParams<float>&, const GaussianCloud&, float, std::int64_t,
                         std::int64_t, SplatRecord<float>*, std::uint64_t*) {
    // never called: avx2_kernel_available() is false
}

}  // namespace avsplat::detail::cpu

#endif
