// The scalar type a kernel computes in. Every kernel runs the same templated source in float32
// (the fast path) or float64 (the reference path that tests measure the fast path against);
// outputs are float32 either way.
#pragma once

namespace avsplat {

enum class Precision { Float32, Float64 };

}  // namespace avsplat
