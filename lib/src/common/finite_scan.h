// Whether float arrays hold a NaN or an infinity, in passes that vectorise: the bulk check
// before validate's per-Gaussian scan, and fusion's check that lets it skip zero-weight rows.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace avsplat::detail {

/// Whether any of p[0..n) is NaN or infinite (exponent bits all ones), written so that it
/// vectorises: one OR over the whole range, no branch per value. Inline, so that a caller
/// compiled with AVSPLAT_CLONES_V3 gets an AVX2 copy of the loop.
inline bool any_non_finite(const float* p, std::size_t n) {
    std::uint32_t bad = 0;
    for (std::size_t j = 0; j < n; ++j) {
        std::uint32_t u;
        std::memcpy(&u, p + j, sizeof u);
        bad |= std::uint32_t((u & 0x7f800000u) == 0x7f800000u);
    }
    return bad != 0;
}

/// any_non_finite over p[0..n) on the OpenMP threads (threads_for(n / 64)), in chunks of
/// 64 KiB, each in the AVX2 clone where the CPU has it. Reads every byte once, in order.
bool any_non_finite_parallel(const float* p, std::size_t n);

}  // namespace avsplat::detail
