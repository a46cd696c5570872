// Gated multi-head cross-attention of each view to its assists (avsplat/assist/condition_tokens.h).
//
// K and V of a view do not depend on who attends to it, so they are computed once per view that is
// an assist of some view (2 P C^2 multiply-adds each) instead of once per (view, assist) pair. The
// attention then works on blocks of 128 query rows: the block's logits against all K P keys of one
// head fit in L2/L3, and the block is the unit of parallel work. Block boundaries are fixed, and
// Eigen's GEMM runs single-threaded inside the parallel region with blocking that depends on the
// shapes only, so every output value is computed by the same operations whatever the thread count.
#include "avsplat/assist/condition_tokens.h"

#include "assist/token_checks.h"
#include "avsplat/core/interrupt.h"
#include "common/interrupt_poll.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

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

// Rows [r0, r0 + n) of view v's tokens, in T (a copy only when T is not float).
template <class T>
struct TokenRows {
    TokenRows(const float* tokens, std::int64_t v, int P, int C, int r0, int n)
        : map(tokens + (v * P + r0) * std::int64_t(C), n, C) {
        if constexpr (!std::is_same_v<T, float>) copy = map.template cast<T>();
    }
    const auto& get() const {
        if constexpr (std::is_same_v<T, float>) return map;
        else return copy;
    }
    Eigen::Map<const RowMatrix<float>> map;
    RowMatrix<T> copy;
};

template <class T>
void condition(const float* tokens, int S, int P, int C, const std::int64_t* assists, int K,
               const ConditionWeights& w, const ConditionOptions& o, float* out) {
    const int H = o.heads;
    const int d = C / H;
    const T scale = static_cast<T>(1.0 / std::sqrt(double(d)));
    const T gate = static_cast<T>(o.gate);
    const RowMatrix<T> wq = weight<T>(w.wq, C), wk = weight<T>(w.wk, C), wv = weight<T>(w.wv, C),
                       wo = weight<T>(w.wo, C);
    const RowVector<T> bq = bias<T>(w.bq, C), bk = bias<T>(w.bk, C), bv = bias<T>(w.bv, C), bo = bias<T>(w.bo, C);
    const int blocks = (P + kRowBlock - 1) / kRowBlock;

    // K and V of every view that assists some view, in slots.
    std::vector<std::int64_t> slot(std::size_t(S), -1);
    std::vector<std::int64_t> slot_view;
    for (std::int64_t i = 0; i < std::int64_t(S) * K; ++i) {
        const std::int64_t t = assists[i];
        if (slot[std::size_t(t)] < 0) slot[std::size_t(t)] = 0;
    }
    for (int t = 0; t < S; ++t)
        if (slot[std::size_t(t)] == 0) {
            slot[std::size_t(t)] = std::int64_t(slot_view.size());
            slot_view.push_back(t);
        }
    const std::int64_t U = std::int64_t(slot_view.size());
    std::vector<T> keys(std::size_t(U) * std::size_t(P) * std::size_t(C));
    std::vector<T> values(keys.size());
    auto key_map = [&](std::int64_t t) {
        return Eigen::Map<const RowMatrix<T>>(keys.data() + slot[std::size_t(t)] * P * C, P, C);
    };
    auto value_map = [&](std::int64_t t) {
        return Eigen::Map<const RowMatrix<T>>(values.data() + slot[std::size_t(t)] * P * C, P, C);
    };

    throw_if_interrupted();  // the loops poll on the calling thread, which may get no iteration
    InterruptPoll poll;
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t item = 0; item < U * blocks; ++item) {
        if (poll.stop()) continue;
        poll.guard([&] {
            const std::int64_t u = item / blocks;
            const int r0 = int(item % blocks) * kRowBlock, n = std::min(kRowBlock, P - r0);
            const TokenRows<T> x(tokens, slot_view[std::size_t(u)], P, C, r0, n);
            Eigen::Map<RowMatrix<T>> k(keys.data() + (u * P + r0) * C, n, C);
            Eigen::Map<RowMatrix<T>> v(values.data() + (u * P + r0) * C, n, C);
            k.noalias() = x.get() * wk;
            k.rowwise() += bk;
            v.noalias() = x.get() * wv;
            v.rowwise() += bv;
        });
    }
    poll.throw_if_stopped();

#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t item = 0; item < std::int64_t(S) * blocks; ++item) {
        if (poll.stop()) continue;
        poll.guard([&] {
            const std::int64_t s = item / blocks;
            const int r0 = int(item % blocks) * kRowBlock, n = std::min(kRowBlock, P - r0);
            const TokenRows<T> x(tokens, s, P, C, r0, n);
            Eigen::Map<RowMatrix<float>> y(out + (s * P + r0) * std::int64_t(C), n, C);
            if (K == 0) {
                y = x.map;
                return;
            }
            RowMatrix<T> q(n, C);
            q.noalias() = x.get() * wq;
            q.rowwise() += bq;
            RowMatrix<T> heads_out(n, C);
            RowMatrix<T> logits(n, std::int64_t(K) * P);
            const std::int64_t* a = assists + s * K;
            for (int h = 0; h < H; ++h) {
                const auto qh = q.middleCols(h * d, d);
                for (int j = 0; j < K; ++j)
                    logits.middleCols(std::int64_t(j) * P, P).noalias() =
                        qh * key_map(a[j]).middleCols(h * d, d).transpose();
                // Max-subtracted softmax; the normaliser of each row is summed in double.
                const Eigen::Matrix<T, Eigen::Dynamic, 1> row_max = logits.rowwise().maxCoeff();
                logits.array() = ((logits.array().colwise() - row_max.array()) * scale).exp();
                auto oh = heads_out.middleCols(h * d, d);
                for (int j = 0; j < K; ++j) {
                    const auto e = logits.middleCols(std::int64_t(j) * P, P);
                    const auto vh = value_map(a[j]).middleCols(h * d, d);
                    if (j == 0) oh.noalias() = e * vh;
                    else oh.noalias() += e * vh;
                }
                for (int i = 0; i < n; ++i) {
                    const double sum = logits.row(i).template cast<double>().sum();
                    oh.row(i) *= static_cast<T>(1.0 / sum);
                }
            }
            RowMatrix<T> c(n, C);
            c.noalias() = heads_out * wo;
            c.rowwise() += bo;
            y = (x.get() + gate * c).template cast<float>();
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
