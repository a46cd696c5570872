// Gated multi-head cross-attention of each view to its assists (avsplat/assist/condition_tokens.h).
//
// K and V of a view do not depend on who attends to it, so they are computed once per view that is
// an assist of some view (2 P C^2 multiply-adds each) instead of once per (view, assist) pair. The
// attention then works on blocks of 128 query rows: the block's logits against all K P keys of one
// head fit in L2/L3, and the block is the unit of parallel work. Block boundaries are fixed, and
// Eigen's GEMM runs single-threaded inside the parallel region with blocking that depends on the
// shapes only, so every output value is computed by the same operations whatever the thread count.
#include "avsplat/assist/condition_tokens.h"

#include "assist/attention_kernels.h"
#include "assist/token_checks.h"
#include "avsplat/core/interrupt.h"
#include "core/interrupt_poll.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#if defined(AVSPLAT_ASSIST_V3)
extern "C" {
// condition_tokens_v3.cpp: the float32 kernels built for x86-64-v3.
void avsplat_assist_v3_project(const float* x, int n, int C, const float* w, const float* b, float* out);
void avsplat_assist_v3_attend(const float* x, int n, int P, int C, int heads, int K, const float* const* keys,
                              const float* const* values, const float* wq, const float* bq, const float* wo,
                              const float* bo, double gate, float* y);
}
#endif

namespace avsplat {

namespace {

template <class T>
using RowMatrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
template <class T>
using RowVector = Eigen::Matrix<T, 1, Eigen::Dynamic>;

constexpr int kRowBlock = 128;

template <class T>
RowMatrix<T> weight(const float* w, int C) {
    return Eigen::Map<const RowMatrix<float>>(w, C, C).template cast<T>();
}

template <class T>
RowVector<T> bias(const float* b, int C) {
    if (b == nullptr) return RowVector<T>::Zero(C);
    return Eigen::Map<const RowVector<float>>(b, C).template cast<T>();
}

// The kernels a call uses: the x86-64-v3 build of the float32 ones where the CPU has AVX2 and FMA.
template <class T>
struct Kernels {
    void (*project)(const float*, int, int, const T*, const T*, T*) = assist_detail::project_rows<T>;
    void (*attend)(const float*, int, int, int, int, int, const T* const*, const T* const*, const T*, const T*,
                   const T*, const T*, double, float*) = assist_detail::attend_rows<T>;
};

template <class T>
Kernels<T> kernels() {
    Kernels<T> k;
#if defined(AVSPLAT_ASSIST_V3)
    if constexpr (std::is_same_v<T, float>) {
        static const bool v3 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
        if (v3) {
            k.project = avsplat_assist_v3_project;
            k.attend = avsplat_assist_v3_attend;
        }
    }
#endif
    return k;
}

template <class T>
void condition(const float* tokens, int S, int P, int C, const std::int64_t* assists, int K,
               const ConditionWeights& w, const ConditionOptions& o, float* out) {
    const Kernels<T> kernel = kernels<T>();
    const RowMatrix<T> wq = weight<T>(w.wq, C), wk = weight<T>(w.wk, C), wv = weight<T>(w.wv, C),
                       wo = weight<T>(w.wo, C);
    const RowVector<T> bq = bias<T>(w.bq, C), bk = bias<T>(w.bk, C), bv = bias<T>(w.bv, C), bo = bias<T>(w.bo, C);
    const int blocks = (P + kRowBlock - 1) / kRowBlock;

    // K and V of every view that assists some view, in slots.
    std::vector<std::int64_t> slot(std::size_t(S), -1);
    std::vector<std::int64_t> slot_view;
    for (std::int64_t i = 0; i < std::int64_t(S) * K; ++i) slot[std::size_t(assists[i])] = 0;
    for (int t = 0; t < S; ++t)
        if (slot[std::size_t(t)] == 0) {
            slot[std::size_t(t)] = std::int64_t(slot_view.size());
            slot_view.push_back(t);
        }
    const std::int64_t U = std::int64_t(slot_view.size());
    std::vector<T> keys(std::size_t(U) * std::size_t(P) * std::size_t(C));
    std::vector<T> values(keys.size());

    throw_if_interrupted();  // the loops poll on the calling thread, which may get no iteration
    InterruptPoll poll;
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t item = 0; item < U * blocks; ++item) {
        if (poll.stop()) continue;
        poll.guard([&] {
            const std::int64_t u = item / blocks;
            const int r0 = int(item % blocks) * kRowBlock, n = std::min(kRowBlock, P - r0);
            const float* x = tokens + (slot_view[std::size_t(u)] * P + r0) * std::int64_t(C);
            kernel.project(x, n, C, wk.data(), bk.data(), keys.data() + (u * P + r0) * C);
            kernel.project(x, n, C, wv.data(), bv.data(), values.data() + (u * P + r0) * C);
        });
    }
    poll.throw_if_stopped();

#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t item = 0; item < std::int64_t(S) * blocks; ++item) {
        if (poll.stop()) continue;
        poll.guard([&] {
            const std::int64_t s = item / blocks;
            const int r0 = int(item % blocks) * kRowBlock, n = std::min(kRowBlock, P - r0);
            const float* x = tokens + (s * P + r0) * std::int64_t(C);
            float* y = out + (s * P + r0) * std::int64_t(C);
            if (K == 0) {
                std::copy(x, x + std::int64_t(n) * C, y);
                return;
            }
            std::vector<const T*> k(static_cast<std::size_t>(K)), v(static_cast<std::size_t>(K));
            for (int j = 0; j < K; ++j) {
                const std::int64_t at = slot[std::size_t(assists[s * K + j])] * P * C;
                k[std::size_t(j)] = keys.data() + at;
                v[std::size_t(j)] = values.data() + at;
            }
            kernel.attend(x, n, P, C, o.heads, K, k.data(), v.data(), wq.data(), bq.data(), wo.data(), bo.data(),
                          o.gate, y);
        });
    }
    poll.throw_if_stopped();
}

}  // namespace

void condition_tokens(const float* tokens, int views, int tokens_per_view, int channels,
                      const std::int64_t* assists, int assists_per_view, const ConditionWeights& weights,
                      const ConditionOptions& options, float* out) {
    assist_detail::check_token_shape(tokens, views, tokens_per_view, channels);
    if (options.heads < 1) throw std::invalid_argument("heads: must be >= 1, got " + std::to_string(options.heads));
    if (views > 0 && channels % options.heads != 0)
        throw std::invalid_argument("heads: " + std::to_string(options.heads) + " does not divide the " +
                                    std::to_string(channels) + " channels");
    if (!std::isfinite(options.gate)) throw std::invalid_argument("gate: must be finite");
    if (assists_per_view < 0) throw std::invalid_argument("assists: the number per view must be >= 0");
    if (views == 0) return;
    if (assists_per_view > 0 && assists == nullptr) throw std::invalid_argument("assists: missing");
    if (out == nullptr) throw std::invalid_argument("out: missing");
    for (std::int64_t i = 0; i < std::int64_t(views) * assists_per_view; ++i)
        if (assists[i] < 0 || assists[i] >= views)
            throw std::invalid_argument("assists[" + std::to_string(i / assists_per_view) + ", " +
                                        std::to_string(i % assists_per_view) + "] = " + std::to_string(assists[i]) +
                                        ": out of range for " + std::to_string(views) + " views");
    const std::pair<const float*, const char*> matrices[] = {
        {weights.wq, "wq"}, {weights.wk, "wk"}, {weights.wv, "wv"}, {weights.wo, "wo"}};
    for (const auto& [w, name] : matrices) {
        if (w == nullptr) throw std::invalid_argument(std::string(name) + ": missing");
        assist_detail::check_finite(w, {channels, channels}, name);
    }
    const std::pair<const float*, const char*> biases[] = {
        {weights.bq, "bq"}, {weights.bk, "bk"}, {weights.bv, "bv"}, {weights.bo, "bo"}};
    for (const auto& [b, name] : biases)
        if (b != nullptr) assist_detail::check_finite(b, {channels}, name);
    assist_detail::check_finite(tokens, {views, tokens_per_view, channels}, "tokens");
    if (options.precision == Precision::Float64)
        condition<double>(tokens, views, tokens_per_view, channels, assists, assists_per_view, weights, options, out);
    else
        condition<float>(tokens, views, tokens_per_view, channels, assists, assists_per_view, weights, options, out);
}

}  // namespace avsplat
