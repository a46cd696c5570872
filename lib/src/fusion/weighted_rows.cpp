#include "fusion/weighted_rows.h"

#include "common/cpu_dispatch.h"

#include <cmath>
#include <cstring>

namespace avsplat::fusion_detail {

namespace {

// Four channels at a time, in GCC's vector extension: the x86-64-v3 build keeps them in AVX
// registers (four doubles each), the baseline build pairs of SSE2 registers; each lane does the
// scalar form's multiply and add (no FMA: the library is built with -ffp-contract=off), so every
// channel gets the bits it would get alone, on every ISA.
typedef double Double4 __attribute__((vector_size(32)));
typedef float Float4 __attribute__((vector_size(16)));
typedef std::int32_t Int4 __attribute__((vector_size(16)));

// Channels [c0, c0 + 4 Q) of the weighted sum, Q accumulators of four doubles held in registers
// across the voxel's samples; each channel is summed in sample order.
template <int Q>
__attribute__((always_inline)) inline bool weighted_quads(const float* __restrict rows, std::size_t width,
                                                          const std::int32_t* __restrict ids,
                                                          const double* __restrict w, std::size_t n, double inv,
                                                          std::size_t c0, float* __restrict out) {
    Double4 a[Q];
    for (int q = 0; q < Q; ++q) a[q] = Double4{0.0, 0.0, 0.0, 0.0};
    for (std::size_t k = 0; k < n; ++k) {
        const float* r = rows + width * std::size_t(ids[k]) + c0;
        const double wk = w[k];
        const Double4 wv = {wk, wk, wk, wk};
        for (int q = 0; q < Q; ++q) {
            Float4 x;
            std::memcpy(&x, r + 4 * q, sizeof x);
            a[q] += wv * __builtin_convertvector(x, Double4);
        }
    }
    const Double4 iv = {inv, inv, inv, inv};
    // A float is finite when its exponent bits are not all ones.
    Int4 bad = {0, 0, 0, 0};
    const Int4 exponent = {0x7f800000, 0x7f800000, 0x7f800000, 0x7f800000};
    for (int q = 0; q < Q; ++q) {
        const Float4 y = __builtin_convertvector(a[q] * iv, Float4);
        std::memcpy(out + c0 + 4 * q, &y, sizeof y);
        Int4 bits;
        std::memcpy(&bits, &y, sizeof bits);
        bad |= (bits & exponent) == exponent;
    }
    return (bad[0] | bad[1] | bad[2] | bad[3]) == 0;
}

}  // namespace

AVSPLAT_CLONES_V3
bool weighted_rows(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                   const double* __restrict w, std::size_t n, double inv, float* __restrict out) {
    bool ok = true;
    std::size_t c0 = 0;
    // Blocks of 32 channels (eight accumulators and the weight fill 9 of the 16 AVX registers),
    // then what is left in blocks of 16, 8 and 4, then single channels.
    for (; c0 + 32 <= width; c0 += 32) ok &= weighted_quads<8>(rows, width, ids, w, n, inv, c0, out);
    if (c0 + 16 <= width) {
        ok &= weighted_quads<4>(rows, width, ids, w, n, inv, c0, out);
        c0 += 16;
    }
    if (c0 + 8 <= width) {
        ok &= weighted_quads<2>(rows, width, ids, w, n, inv, c0, out);
        c0 += 8;
    }
    if (c0 + 4 <= width) {
        ok &= weighted_quads<1>(rows, width, ids, w, n, inv, c0, out);
        c0 += 4;
    }
    for (; c0 < width; ++c0) {
        double a = 0.0;
        for (std::size_t k = 0; k < n; ++k) a += w[k] * double(rows[width * std::size_t(ids[k]) + c0]);
        out[c0] = float(a * inv);
        ok &= std::isfinite(out[c0]);
    }
    return ok;
}

}  // namespace avsplat::fusion_detail
