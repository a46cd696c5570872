// The float32 kernels of condition_tokens compiled for x86-64-v3 (AVX2, FMA: Eigen's 8-wide
// GEMM kernels), called only when the CPU has both (condition_tokens.cpp checks at run time).
//
// Built apart (lib/CMakeLists.txt): this object is linked with `ld -r` and every symbol but the
// two entry points below is made local, so that Eigen's and the standard library's templates
// instantiated here with AVX2 code never stand in for the baseline instantiations elsewhere.
#include "assist/attention_kernels.h"

extern "C" {

void avsplat_assist_v3_project(const float* x, int n, int C, const float* w, const float* b, float* out) {
    avsplat::assist_detail::project_rows<float>(x, n, C, w, b, out);
}

void avsplat_assist_v3_attend(const float* x, int n, int P, int C, int heads, int K, const float* const* keys,
                              const float* const* values, const float* wq, const float* bq, const float* wo,
                              const float* bo, double gate, float* y) {
    avsplat::assist_detail::attend_rows<float>(x, n, P, C, heads, K, keys, values, wq, bq, wo, bo, gate, y);
}

}  // extern "C"
