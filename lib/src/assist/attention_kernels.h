// The two kernels of condition_tokens, on one block of token rows. Included by
// condition_tokens.cpp (baseline x86-64, both precisions) and by condition_tokens_v3.cpp (the
// float32 kernels again, compiled for x86-64-v3: AVX2 and FMA); internal linkage in each.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <type_traits>

namespace avsplat::assist_detail {
namespace {

template <class T>
using KernelMatrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
template <class T>
using KernelRow = Eigen::Matrix<T, 1, Eigen::Dynamic>;

// n rows of float tokens as T (a copy only when T is not float).
template <class T>
struct TokenRows {
    TokenRows(const float* rows, int n, int C) : map(rows, n, C) {
        if constexpr (!std::is_same_v<T, float>) copy = map.template cast<T>();
    }
    const auto& get() const {
        if constexpr (std::is_same_v<T, float>) return map;
        else return copy;
    }
    Eigen::Map<const KernelMatrix<float>> map;
    KernelMatrix<T> copy;
};

/// out (n x C) = x (n x C float rows) w (C x C) + b (C).
template <class T>
void project_rows(const float* x, int n, int C, const T* w, const T* b, T* out) {
    const TokenRows<T> rows(x, n, C);
    Eigen::Map<KernelMatrix<T>> o(out, n, C);
    o.noalias() = rows.get() * Eigen::Map<const KernelMatrix<T>>(w, C, C);
    o.rowwise() += Eigen::Map<const KernelRow<T>>(b, C);
}

/// y (n x C float) = x + gate (softmax-attention of x Wq + bq over the K assists' keys and values,
/// heads concatenated) Wo + bo. keys[j], values[j]: P x C of assist j.
template <class T>
void attend_rows(const float* x, int n, int P, int C, int heads, int K, const T* const* keys, const T* const* values,
                 const T* wq, const T* bq, const T* wo, const T* bo, double gate, float* y) {
    const int d = C / heads;
    const T scale = static_cast<T>(1.0 / std::sqrt(double(d)));
    const TokenRows<T> rows(x, n, C);
    KernelMatrix<T> q(n, C);
    q.noalias() = rows.get() * Eigen::Map<const KernelMatrix<T>>(wq, C, C);
    q.rowwise() += Eigen::Map<const KernelRow<T>>(bq, C);
    KernelMatrix<T> heads_out(n, C);
    KernelMatrix<T> logits(n, std::int64_t(K) * P);
    for (int h = 0; h < heads; ++h) {
        const auto qh = q.middleCols(h * d, d);
        for (int j = 0; j < K; ++j)
            logits.middleCols(std::int64_t(j) * P, P).noalias() =
                qh * Eigen::Map<const KernelMatrix<T>>(keys[j], P, C).middleCols(h * d, d).transpose();
        // Max-subtracted softmax; the normaliser of each row is summed in double.
        const Eigen::Matrix<T, Eigen::Dynamic, 1> row_max = logits.rowwise().maxCoeff();
        logits.array() = ((logits.array().colwise() - row_max.array()) * scale).exp();
        auto oh = heads_out.middleCols(h * d, d);
        for (int j = 0; j < K; ++j) {
            const auto e = logits.middleCols(std::int64_t(j) * P, P);
            const auto vh = Eigen::Map<const KernelMatrix<T>>(values[j], P, C).middleCols(h * d, d);
            if (j == 0) oh.noalias() = e * vh;
            else oh.noalias() += e * vh;
        }
        for (int i = 0; i < n; ++i) {
            const double sum = logits.row(i).template cast<double>().sum();
            oh.row(i) *= static_cast<T>(1.0 / sum);
        }
    }
    KernelMatrix<T> c(n, C);
    c.noalias() = heads_out * Eigen::Map<const KernelMatrix<T>>(wo, C, C);
    c.rowwise() += Eigen::Map<const KernelRow<T>>(bo, C);
    Eigen::Map<KernelMatrix<float>>(y, n, C) = (rows.get() + static_cast<T>(gate) * c).template cast<float>();
}

}  // namespace
}  // namespace avsplat::assist_detail
