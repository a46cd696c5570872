#include "fusion/weighted_rows.h"

#include "common/cpu_dispatch.h"

#include <cmath>

namespace avsplat::fusion_detail {

AVSPLAT_CLONES_V3
bool weighted_rows(const float* __restrict rows, std::size_t width, const std::int32_t* __restrict ids,
                   const double* __restrict w, std::size_t n, double inv, float* __restrict out) {
    constexpr std::size_t kBlock = 16;
    bool ok = true;
    std::size_t c0 = 0;
    for (; c0 + kBlock <= width; c0 += kBlock) {
        double a[kBlock] = {};
        for (std::size_t k = 0; k < n; ++k) {
            const float* r = rows + width * std::size_t(ids[k]) + c0;
            const double wk = w[k];
            for (std::size_t j = 0; j < kBlock; ++j) a[j] += wk * double(r[j]);
        }
        for (std::size_t j = 0; j < kBlock; ++j) {
            out[c0 + j] = float(a[j] * inv);
            ok &= std::isfinite(out[c0 + j]);
        }
    }
    if (c0 < width) {
        const std::size_t rest = width - c0;
        double a[kBlock] = {};
        for (std::size_t k = 0; k < n; ++k) {
            const float* r = rows + width * std::size_t(ids[k]) + c0;
            const double wk = w[k];
            for (std::size_t j = 0; j < rest; ++j) a[j] += wk * double(r[j]);
        }
        for (std::size_t j = 0; j < rest; ++j) {
            out[c0 + j] = float(a[j] * inv);
            ok &= std::isfinite(out[c0 + j]);
        }
    }
    return ok;
}

}  // namespace avsplat::fusion_detail
