// AVSPLAT_HD marks the small inline math functions that the CPU reference and the CUDA
// renderer share, so that both back ends run literally the same source.
#pragma once

#if defined(__CUDACC__)
#define AVSPLAT_HD __host__ __device__ __forceinline__
#else
#define AVSPLAT_HD inline
#endif
