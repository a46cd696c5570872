// The AVX-512 kernel of the projection stage (project_block_kernels.h): project_block.h compiled
// for avx512f (one 512-bit vector of 8 doubles per quantity). Every header is included before the pragma, so that only
// project_block.h's file-local functions are compiled for AVX-512 (see project_block.h).
#include "render/cpu/project_block_kernels.h"
#include "render/cpu/project_splats.h"

#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define AVSPLAT_PROJECT_AVX512 1
#include <immintrin.h>
#endif

#if AVSPLAT_PROJECT_AVX512

#pragma GCC push_options
#pragma GCC target("avx512f")
// GCC 12's avx512fintrin.h passes _mm512_undefined_pd() as the unused source of its unmasked
// intrinsics and warns about it (GCC bug 105593, fixed in GCC 13), as in blend_tile_avx512.cpp.
#pragma GCC diagnostic ignored "-Wuninitialized"
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include "render/cpu/project_block.h"

namespace avsplat::detail::cpu {

void project_blocks_avx512(const preprocess::ViewParams<float>& view, const GaussianCloud& cloud, float alpha_threshold,
                         std::int64_t begin, std::int64_t blocks, SplatRecord<float>* splats, std::uint64_t* keys) {
    project_blocks(view, cloud, alpha_threshold, begin, blocks, splats, keys);
}

}  // namespace avsplat::detail::cpu

#pragma GCC pop_options

#else  // no AVX-512 kernel in this build

namespace avsplat::detail::cpu {

void project_blocks_avx512(const preprocess::ViewParams<float>&, const GaussianCloud&, float, std::int64_t,
                         std::int64_t, SplatRecord<float>*, std::uint64_t*) {
    // never called: avx512_kernel_available() is false
}

}  // namespace avsplat::detail::cpu

#endif
