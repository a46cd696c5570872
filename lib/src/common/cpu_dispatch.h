// AVSPLAT_CLONES_V3: compile a hot loop twice where GCC can pick at load time (ifunc), for
// x86-64-v3 (AVX2, FMA) and for the baseline, so that one binary runs anywhere and uses the wide
// vector units where they exist. The library is built with -ffp-contract=off (lib/CMakeLists.txt:
// GCC would otherwise contract a * b + c into FMAs in the v3 clone, even in ISO C++ mode), so the
// two versions form no FMA of their own and give the same results.
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define AVSPLAT_CLONES_V3 __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define AVSPLAT_CLONES_V3
#endif
