// Order-preserving integer keys of floats, shared by the renderer's depth sort and the fusion's
// canonical order. Header-only, no STL, AVSPLAT_HD.
#pragma once

#include "avsplat/common/hostdevice.h"

#include <stdint.h>
#include <string.h>

namespace avsplat {

/// An unsigned integer that orders like the float f, for every non-NaN float: negative values
/// get all bits flipped, non-negative ones the sign bit set. -0 sorts just before +0; -inf maps
/// to 0x007FFFFF and +inf to 0xFF800000, so 0 and UINT32_MAX are never keys of a non-NaN float.
AVSPLAT_HD uint32_t float_order_key(float f) {
#if defined(__CUDA_ARCH__)
    const uint32_t b = __float_as_uint(f);
#else
    uint32_t b;
    memcpy(&b, &f, sizeof b);
#endif
    return (b & 0x80000000u) ? ~b : (b | 0x80000000u);
}

/// A key whose unsigned order is the decreasing order of non-NaN floats (+0 before -0): the
/// complement of float_order_key. Never UINT32_MAX, which callers may use as a pad that sorts
/// after every key.
AVSPLAT_HD uint32_t float_descending_key(float f) { return ~float_order_key(f); }

}  // namespace avsplat
