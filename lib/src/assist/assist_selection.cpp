// Assist-View selection (avsplat/assist/assist_selection.h).
//
// Work per view is independent once the per-view statistics (descriptor, subsampled unit rows,
// reliability) are known, so both phases run as OpenMP loops over views. Every quantity of a view
// is computed by the same sequence of operations whatever the thread count (Eigen's GEMM runs
// single-threaded inside a parallel region, with blocking that depends on the shapes only), and
// equal inputs give equal values: duplicate views tie exactly, and ties go to the smaller index.
#include "avsplat/assist/assist_selection.h"

#include "assist/token_checks.h"
#include "avsplat/core/interrupt.h"
#include "core/interrupt_poll.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace avsplat {

namespace {

template <class T>
using RowMatrix = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

constexpr double kNormFloor = 1e-12;
constexpr double kRelevance = 0.7;

// Rows floor(j P / p_sub), j = 0..p_sub-1, or every row when p_sub >= P.
std::vector<std::int64_t> subsampled_rows(int P, int p_sub) {
    std::vector<std::int64_t> rows;
    const int n = std::min(P, p_sub);
    rows.reserve(std::size_t(n));
    for (int j = 0; j < n; ++j)
        rows.push_back(p_sub >= P ? j : std::int64_t(j) * std::int64_t(P) / std::int64_t(p_sub));
    return rows;
}

// What the selection needs of every view.
template <class T>
struct TokenStatistics {
    int views = 0, channels = 0, rows = 0;
    std::vector<double> descriptors;   // S x C, d_s
    std::vector<double> variance;      // S, v_s
    std::vector<T> unit_rows;          // S x R x C, Xh_s
    std::vector<double> reliability;   // S, q_s

    const T* view_rows(std::int64_t s) const { return unit_rows.data() + s * std::int64_t(rows) * channels; }
    const double* descriptor(std::int64_t s) const { return descriptors.data() + s * std::int64_t(channels); }
};

template <class T>
TokenStatistics<T> token_statistics(const float* tokens, int S, int P, int C, int p_sub) {
    const std::vector<std::int64_t> rows = subsampled_rows(P, p_sub);
    const int R = int(rows.size());
    TokenStatistics<T> st;
    st.views = S;
    st.channels = C;
    st.rows = R;
    st.descriptors.assign(std::size_t(S) * std::size_t(C), 0.0);
    st.variance.assign(std::size_t(S), 0.0);
    st.unit_rows.resize(std::size_t(S) * std::size_t(R) * std::size_t(C));
    InterruptPoll poll;
#pragma omp parallel for schedule(dynamic, 1)
    for (int s = 0; s < S; ++s) {
        if (poll.stop()) continue;
        poll.guard([&] {
            const float* x = tokens + std::int64_t(s) * P * C;
            double* d = st.descriptors.data() + std::int64_t(s) * C;
            for (int p = 0; p < P; ++p)
                for (int c = 0; c < C; ++c) d[c] += double(x[std::int64_t(p) * C + c]);
            double norm = 0;
            for (int c = 0; c < C; ++c) {
                d[c] /= double(P);
                norm += d[c] * d[c];
            }
            norm = std::max(std::sqrt(norm), kNormFloor);
            for (int c = 0; c < C; ++c) d[c] /= norm;

            // Unit rows in double (the variance is taken from these), stored in T for the GEMMs.
            std::vector<double> unit(std::size_t(R) * std::size_t(C));
            for (int j = 0; j < R; ++j) {
                const float* row = x + rows[std::size_t(j)] * C;
                double n2 = 0;
                for (int c = 0; c < C; ++c) n2 += double(row[c]) * double(row[c]);
                const double n = std::max(std::sqrt(n2), kNormFloor);
                for (int c = 0; c < C; ++c) unit[std::size_t(j) * C + c] = double(row[c]) / n;
            }
            T* out = st.unit_rows.data() + std::int64_t(s) * R * C;
            for (std::size_t i = 0; i < unit.size(); ++i) out[i] = static_cast<T>(unit[i]);
            // Population variance over rows, two passes, averaged over channels.
            double total = 0;
            for (int c = 0; c < C; ++c) {
                double mean = 0;
                for (int j = 0; j < R; ++j) mean += unit[std::size_t(j) * C + c];
                mean /= double(R);
                double ss = 0;
                for (int j = 0; j < R; ++j) {
                    const double e = unit[std::size_t(j) * C + c] - mean;
                    ss += e * e;
                }
                total += ss / double(R);
            }
            st.variance[std::size_t(s)] = total / double(C);
        });
    }
    poll.throw_if_stopped();
    const double vmax = S > 0 ? *std::max_element(st.variance.begin(), st.variance.end()) : 0.0;
    st.reliability.resize(std::size_t(S));
    for (int s = 0; s < S; ++s) st.reliability[std::size_t(s)] = vmax > 0 ? st.variance[std::size_t(s)] / vmax : 0.0;
    return st;
}

template <class T>
double similarity(const TokenStatistics<T>& st, std::int64_t s, std::int64_t t) {
    const double* a = st.descriptor(s);
    const double* b = st.descriptor(t);
    double dot = 0;
    for (int c = 0; c < st.channels; ++c) dot += a[c] * b[c];
    return std::clamp(dot, -1.0, 1.0);
}

// sup_t[p] = max_j Xh_s[p] . Xh_t[j] for p = 0..R-1, one GEMM in T.
template <class T>
void support(const TokenStatistics<T>& st, std::int64_t s, std::int64_t t, double* sup) {
    const Eigen::Map<const RowMatrix<T>> a(st.view_rows(s), st.rows, st.channels);
    const Eigen::Map<const RowMatrix<T>> b(st.view_rows(t), st.rows, st.channels);
    RowMatrix<T> g(st.rows, st.rows);
    g.noalias() = a * b.transpose();
    for (int p = 0; p < st.rows; ++p) sup[p] = double(g.row(p).maxCoeff());
}

// splitmix64's finaliser: the per-view random draws of the jitter.
std::uint64_t mix(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

double uniform_draw(std::uint64_t seed, std::int64_t s, int i) {
    const std::uint64_t r = mix(seed + (2 * std::uint64_t(s) + std::uint64_t(i) + 1) * 0x9E3779B97F4A7C15ull);
    return double(r >> 11) * 0x1.0p-53;
}

void check_options(const AssistOptions& o) {
    if (o.k < 0) throw std::invalid_argument("k: must be >= 0, got " + std::to_string(o.k));
    if (o.m < 0) throw std::invalid_argument("m: must be >= 0, got " + std::to_string(o.m));
    if (o.p_sub < 1) throw std::invalid_argument("p_sub: must be >= 1, got " + std::to_string(o.p_sub));
    if (!std::isfinite(o.lambda_div)) throw std::invalid_argument("lambda_div: must be finite");
    if (!std::isfinite(o.beta)) throw std::invalid_argument("beta: must be finite");
    if (!(o.jitter >= 0 && o.jitter <= 1))
        throw std::invalid_argument("jitter: must lie in [0, 1], got " + std::to_string(o.jitter));
}

template <class T>
AssistSelection select(const float* tokens, int S, int P, int C, const AssistOptions& o) {
    throw_if_interrupted();  // the loops poll on the calling thread, which may get no iteration
    const TokenStatistics<T> st = token_statistics<T>(tokens, S, P, C, o.p_sub);
    const int R = st.rows;
    const int M = std::max(0, std::min(o.m, S - 1));
    const int K = std::min(o.k, M);

    AssistSelection result;
    result.views = S;
    result.per_view = K;
    result.channels = C;
    result.assists.assign(std::size_t(S) * std::size_t(K), -1);
    result.scores.assign(std::size_t(S) * std::size_t(K), 0.f);
    result.descriptors.assign(st.descriptors.begin(), st.descriptors.end());
    result.reliability.assign(st.reliability.begin(), st.reliability.end());
    if (K == 0) return result;

    InterruptPoll poll;
#pragma omp parallel for schedule(dynamic, 1)
    for (int s = 0; s < S; ++s) {
        if (poll.stop()) continue;
        poll.guard([&] {
            // The pool: M views t != s of largest Sigma[s, t], ties to the smaller index.
            std::vector<std::pair<double, int>> order;
            order.reserve(std::size_t(S) - 1);
            for (int t = 0; t < S; ++t)
                if (t != s) order.emplace_back(similarity(st, s, t), t);
            std::partial_sort(order.begin(), order.begin() + M, order.end(), [](const auto& a, const auto& b) {
                return a.first != b.first ? a.first > b.first : a.second < b.second;
            });
            std::vector<int> pool(static_cast<std::size_t>(M));
            std::vector<double> sigma(static_cast<std::size_t>(M));
            for (int i = 0; i < M; ++i) {
                pool[std::size_t(i)] = order[std::size_t(i)].second;
                sigma[std::size_t(i)] = order[std::size_t(i)].first;
            }
            // Pool members in increasing view index: the order in which ties are broken.
            std::vector<int> by_index(static_cast<std::size_t>(M));
            for (int i = 0; i < M; ++i) by_index[std::size_t(i)] = i;
            std::sort(by_index.begin(), by_index.end(), [&](int a, int b) { return pool[std::size_t(a)] < pool[std::size_t(b)]; });

            std::vector<double> sup(std::size_t(M) * std::size_t(R));
            for (int i = 0; i < M; ++i) support(st, s, pool[std::size_t(i)], sup.data() + std::size_t(i) * R);
            auto q = [&](int i) { return st.reliability[std::size_t(pool[std::size_t(i)])]; };

            // Score of pool member i given the coverage c and its min distance to A.
            auto score = [&](int i, const std::vector<double>& c, double min_delta, bool first) {
                const double* si = sup.data() + std::size_t(i) * R;
                double gain = 0;
                for (int p = 0; p < R; ++p) gain += std::max(0.0, si[p] - (first ? 0.0 : c[std::size_t(p)]));
                return kRelevance * sigma[std::size_t(i)] + (first ? 0.0 : o.lambda_div * min_delta) + gain / double(R) +
                       o.beta * q(i);
            };

            std::vector<int> chosen{0};
            std::vector<char> taken(std::size_t(M), 0);
            taken[0] = 1;
            std::vector<double> c(sup.begin(), sup.begin() + R);
            std::vector<double> min_delta(static_cast<std::size_t>(M), std::numeric_limits<double>::infinity());
            auto add_to_a = [&](int u) {
                for (int i = 0; i < M; ++i) {
                    const double delta = std::max(1.0 - similarity(st, pool[std::size_t(i)], pool[std::size_t(u)]), 0.0);
                    min_delta[std::size_t(i)] = std::min(min_delta[std::size_t(i)], delta);
                }
            };
            add_to_a(0);
            std::vector<double> scores{score(0, c, 0.0, true)};
            std::vector<double> last_step(static_cast<std::size_t>(M), 0.0);  // every candidate's score at the last step
            while (int(chosen.size()) < K) {
                int best = -1;
                double best_score = 0;
                for (int i : by_index) {
                    if (taken[std::size_t(i)]) continue;
                    const double v = score(i, c, min_delta[std::size_t(i)], false);
                    last_step[std::size_t(i)] = v;
                    if (best < 0 || v > best_score) {
                        best = i;
                        best_score = v;
                    }
                }
                chosen.push_back(best);
                scores.push_back(best_score);
                taken[std::size_t(best)] = 1;
                const double* sb = sup.data() + std::size_t(best) * R;
                for (int p = 0; p < R; ++p) c[std::size_t(p)] = std::max(c[std::size_t(p)], sb[p]);
                add_to_a(best);
            }

            if (o.jitter > 0 && uniform_draw(o.seed, s, 0) < o.jitter && M > K) {
                std::vector<int> rest;
                for (int i : by_index)
                    if (!taken[std::size_t(i)]) rest.push_back(i);
                const std::size_t n = rest.size();
                const std::size_t pick = std::min(n - 1, std::size_t(uniform_draw(o.seed, s, 1) * double(n)));
                const int drawn = rest[pick];
                chosen.back() = drawn;
                scores.back() = K == 1 ? score(drawn, c, 0.0, true) : last_step[std::size_t(drawn)];
            }
            for (int a = 0; a < K; ++a) {
                result.assists[std::size_t(s) * K + a] = pool[std::size_t(chosen[std::size_t(a)])];
                result.scores[std::size_t(s) * K + a] = static_cast<float>(scores[std::size_t(a)]);
            }
        });
    }
    poll.throw_if_stopped();
    return result;
}

}  // namespace

AssistSelection select_assist_views(const float* tokens, int views, int tokens_per_view, int channels,
                                    const AssistOptions& options) {
    assist_detail::check_token_shape(tokens, views, tokens_per_view, channels);
    check_options(options);
    if (views == 0) {
        AssistSelection empty;
        empty.channels = std::max(channels, 0);
        return empty;
    }
    assist_detail::check_finite(tokens, {views, tokens_per_view, channels}, "tokens");
    return options.precision == Precision::Float64 ? select<double>(tokens, views, tokens_per_view, channels, options)
                                                   : select<float>(tokens, views, tokens_per_view, channels, options);
}

double assist_objective(const float* tokens, int views, int tokens_per_view, int channels, int s,
                        const std::vector<std::int64_t>& assists, double beta, double lambda_div, int p_sub) {
    assist_detail::check_token_shape(tokens, views, tokens_per_view, channels);
    if (s < 0 || s >= views)
        throw std::invalid_argument("s: view " + std::to_string(s) + " out of range for " + std::to_string(views) +
                                    " views");
    if (assists.empty()) throw std::invalid_argument("A: must hold at least one view");
    for (std::size_t i = 0; i < assists.size(); ++i) {
        const std::int64_t t = assists[i];
        const std::string at = "A[" + std::to_string(i) + "] = " + std::to_string(t);
        if (t < 0 || t >= views) throw std::invalid_argument(at + ": out of range for " + std::to_string(views) + " views");
        if (t == s) throw std::invalid_argument(at + ": is the view s itself");
        if (std::find(assists.begin(), assists.begin() + std::ptrdiff_t(i), t) != assists.begin() + std::ptrdiff_t(i))
            throw std::invalid_argument(at + ": repeated");
    }
    if (!std::isfinite(beta)) throw std::invalid_argument("beta: must be finite");
    if (!std::isfinite(lambda_div)) throw std::invalid_argument("lambda_div: must be finite");
    if (p_sub < 1) throw std::invalid_argument("p_sub: must be >= 1, got " + std::to_string(p_sub));
    assist_detail::check_finite(tokens, {views, tokens_per_view, channels}, "tokens");

    throw_if_interrupted();
    const TokenStatistics<double> st = token_statistics<double>(tokens, views, tokens_per_view, channels, p_sub);
    const int n = int(assists.size());
    const int R = st.rows;
    std::vector<double> sup(std::size_t(n) * std::size_t(R));
    InterruptPoll poll;
#pragma omp parallel for schedule(dynamic, 1)
    for (int i = 0; i < n; ++i) {
        if (poll.stop()) continue;
        poll.guard([&] { support(st, s, assists[std::size_t(i)], sup.data() + std::size_t(i) * R); });
    }
    poll.throw_if_stopped();
    double coverage = 0;
    for (int p = 0; p < R; ++p) {
        double best = -std::numeric_limits<double>::infinity();
        for (int i = 0; i < n; ++i) best = std::max(best, sup[std::size_t(i) * R + p]);
        coverage += best;
    }
    double reliability = 0;
    for (std::int64_t t : assists) reliability += st.reliability[std::size_t(t)];
    double redundancy = 0;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j)
            if (i != j) redundancy += similarity(st, assists[std::size_t(i)], assists[std::size_t(j)]);
    return coverage / double(R) + beta * reliability / double(n) -
           (n > 1 ? lambda_div * redundancy / (double(n) * double(n - 1)) : 0.0);
}

}  // namespace avsplat
