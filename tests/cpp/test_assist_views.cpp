#include "avsplat/assist/assist_selection.h"
#include "avsplat/assist/condition_tokens.h"
#include "avsplat/core/interrupt.h"
#include "assist/attention_kernels.h"

#include <catch2/catch.hpp>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <random>
#include <stdexcept>
#include <vector>

using avsplat::AssistOptions;
using avsplat::ConditionOptions;
using avsplat::ConditionWeights;
using avsplat::Precision;

namespace {

std::vector<float> random_tokens(int S, int P, int C, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> n(0.f, 1.f);
    std::vector<float> centre(std::size_t(S) * C);
    for (float& v : centre) v = n(rng);
    std::vector<float> x(std::size_t(S) * P * C);
    for (int s = 0; s < S; ++s)
        for (int p = 0; p < P; ++p)
            for (int c = 0; c < C; ++c) x[(std::size_t(s) * P + p) * C + c] = centre[std::size_t(s) * C + c] + n(rng);
    return x;
}

struct Weights {
    std::vector<float> q, k, v, o, bq, bo;
    ConditionWeights view() const {
        ConditionWeights w;
        w.wq = q.data();
        w.wk = k.data();
        w.wv = v.data();
        w.wo = o.data();
        w.bq = bq.data();
        w.bo = bo.data();
        return w;
    }
};

Weights random_weights(int C, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> n(0.f, 1.f / std::sqrt(float(C)));
    Weights w;
    for (auto* m : {&w.q, &w.k, &w.v, &w.o}) {
        m->resize(std::size_t(C) * C);
        for (float& x : *m) x = n(rng);
    }
    for (auto* b : {&w.bq, &w.bo}) {
        b->resize(std::size_t(C));
        for (float& x : *b) x = n(rng);
    }
    return w;
}

}  // namespace

TEST_CASE("assist selection: hand-computed pools and greedy on one-hot views", "[assist]") {
    // Four views of two tokens in 3 channels. Views 0 and 1 point along x, view 2 along y,
    // view 3 along x and y: Sigma[0, 1] = 1, Sigma[0, 3] = 1/sqrt(2), Sigma[0, 2] = 0.
    const std::vector<float> x = {1, 0, 0, 1, 0, 0,    // view 0
                                  2, 0, 0, 2, 0, 0,    // view 1
                                  0, 1, 0, 0, 1, 0,    // view 2
                                  1, 0, 0, 0, 1, 0};   // view 3
    AssistOptions o;
    o.k = 2;
    o.m = 2;
    o.beta = 0;
    const auto r = avsplat::select_assist_views(x.data(), 4, 2, 3, o);
    REQUIRE(r.per_view == 2);
    // View 0: pool [1, 3]; A = [1], then 3 (the only candidate).
    CHECK(r.assists[0] == 1);
    CHECK(r.assists[1] == 3);
    // Score of 3 for view 0: 0.7 / sqrt(2) + 0.3 * Delta[3, 1] (1 - 1/sqrt(2)) + coverage gain 0
    // (view 1 already covers both rows of view 0 with support 1).
    const double inv = 1 / std::sqrt(2.0);
    CHECK(r.scores[1] == Approx(0.7 * inv + 0.3 * (1 - inv)).epsilon(1e-6));
    // First assist's score: 0.7 * Sigma + mean_p max(0, sup) = 0.7 + 1.
    CHECK(r.scores[0] == Approx(1.7).epsilon(1e-6));
    // View 2: Sigma[2, 3] = 1/sqrt(2) first, then 0 and 1 tie at Sigma 0: the pool keeps 0.
    CHECK(r.assists[4] == 3);
    CHECK(r.assists[5] == 0);
    // Reliability: views 0-2 have no spread over rows; view 3 does (variance 1/4 in x and y).
    CHECK(r.reliability == std::vector<float>{0, 0, 0, 1});
}

TEST_CASE("assist selection and conditioning do not depend on the thread count", "[assist]") {
    const int S = 7, P = 300, C = 16;
    const auto x = random_tokens(S, P, C, 1);
    const auto w = random_weights(C, 2);
    AssistOptions o;
    o.k = 3;
    o.p_sub = 50;
    o.jitter = 0.5;
    o.seed = 9;
    ConditionOptions co;
    co.heads = 4;
    co.gate = 0.5;
    const int saved = omp_get_max_threads();
    std::vector<avsplat::AssistSelection> sel;
    std::vector<std::vector<float>> out;
    for (int threads : {1, 2, 4}) {
        omp_set_num_threads(threads);
        sel.push_back(avsplat::select_assist_views(x.data(), S, P, C, o));
        out.emplace_back(x.size());
        avsplat::condition_tokens(x.data(), S, P, C, sel.back().assists.data(), sel.back().per_view, w.view(), co,
                                  out.back().data());
    }
    omp_set_num_threads(saved);
    for (std::size_t i = 1; i < sel.size(); ++i) {
        CHECK(sel[i].assists == sel[0].assists);
        CHECK(sel[i].scores == sel[0].scores);
        CHECK(out[i] == out[0]);
    }
}

TEST_CASE("conditioning: float32 within 1e-5 of float64, gate 0 and no assists pass through", "[assist]") {
    const int S = 5, P = 140, C = 24;
    const auto x = random_tokens(S, P, C, 3);
    const auto w = random_weights(C, 4);
    AssistOptions o;
    o.k = 2;
    const auto sel = avsplat::select_assist_views(x.data(), S, P, C, o);
    ConditionOptions co;
    co.heads = 6;
    std::vector<float> a(x.size()), b(x.size());
    avsplat::condition_tokens(x.data(), S, P, C, sel.assists.data(), sel.per_view, w.view(), co, a.data());
    co.precision = Precision::Float64;
    avsplat::condition_tokens(x.data(), S, P, C, sel.assists.data(), sel.per_view, w.view(), co, b.data());
    double worst = 0;
    for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, double(std::abs(a[i] - b[i])));
    CHECK(worst < 1e-5);
    CHECK(worst > 0);  // the two precisions are really different paths
    co.gate = 0;
    avsplat::condition_tokens(x.data(), S, P, C, sel.assists.data(), sel.per_view, w.view(), co, a.data());
    CHECK(a == x);
    co.gate = 1;
    avsplat::condition_tokens(x.data(), S, P, C, nullptr, 0, w.view(), co, a.data());
    CHECK(a == x);
}

TEST_CASE("assist operators: errors name the argument and index", "[assist]") {
    auto x = random_tokens(3, 4, 2, 5);
    x[(std::size_t(2) * 4 + 1) * 2 + 1] = std::nanf("");
    AssistOptions o;
    REQUIRE_THROWS_WITH(avsplat::select_assist_views(x.data(), 3, 4, 2, o), Catch::Contains("tokens[2, 1, 1] = nan"));
    o.p_sub = 0;
    REQUIRE_THROWS_WITH(avsplat::select_assist_views(x.data(), 3, 4, 2, o), Catch::Contains("p_sub"));
    const auto good = random_tokens(3, 4, 2, 5);
    REQUIRE_THROWS_WITH(avsplat::assist_objective(good.data(), 3, 4, 2, 0, {1, 1}, 0.1, 0.3, 4),
                        Catch::Contains("A[1] = 1: repeated"));
    const auto w = random_weights(2, 1);
    const std::vector<std::int64_t> assists = {1, 2, 3};
    std::vector<float> out(good.size());
    ConditionOptions co;
    REQUIRE_THROWS_WITH(avsplat::condition_tokens(good.data(), 3, 4, 2, assists.data(), 1, w.view(), co, out.data()),
                        Catch::Contains("assists[2, 0] = 3"));
    co.heads = 3;
    REQUIRE_THROWS_AS(avsplat::condition_tokens(good.data(), 3, 4, 2, assists.data(), 0, w.view(), co, out.data()),
                      std::invalid_argument);
}

TEST_CASE("assist operators stop under an interrupt check and are unchanged by one that says go", "[assist]") {
    using std::chrono::nanoseconds;
    const int S = 4, P = 200, C = 8;
    const auto x = random_tokens(S, P, C, 6);
    const auto w = random_weights(C, 7);
    AssistOptions o;
    o.k = 2;
    ConditionOptions co;
    co.heads = 2;
    const auto plain = avsplat::select_assist_views(x.data(), S, P, C, o);
    std::vector<float> out_plain(x.size()), out(x.size());
    avsplat::condition_tokens(x.data(), S, P, C, plain.assists.data(), plain.per_view, w.view(), co, out_plain.data());
    {
        avsplat::ScopedInterruptCheck go([] { return false; }, nanoseconds(0));
        const auto again = avsplat::select_assist_views(x.data(), S, P, C, o);
        CHECK(again.assists == plain.assists);
        CHECK(again.scores == plain.scores);
        avsplat::condition_tokens(x.data(), S, P, C, plain.assists.data(), plain.per_view, w.view(), co, out.data());
        CHECK(out == out_plain);
    }
    avsplat::ScopedInterruptCheck stop([] { return true; }, nanoseconds(0));
    CHECK_THROWS_AS(avsplat::select_assist_views(x.data(), S, P, C, o), avsplat::Interrupted);
    CHECK_THROWS_AS(avsplat::condition_tokens(x.data(), S, P, C, plain.assists.data(), plain.per_view, w.view(), co,
                                              out.data()),
                    avsplat::Interrupted);
    CHECK_THROWS_AS(avsplat::assist_objective(x.data(), S, P, C, 0, {1, 2}, 0.1, 0.3, 64), avsplat::Interrupted);
}

TEST_CASE("conditioning: the baseline float32 kernels agree with the ones the CPU runs", "[assist]") {
    // On a CPU with AVX2 and FMA condition_tokens runs the x86-64-v3 build of the kernels; the
    // baseline build (compiled into this test) must give the same result within float32 error.
    const int S = 3, P = 100, C = 16, heads = 4;
    const auto x = random_tokens(S, P, C, 8);
    const auto w = random_weights(C, 9);
    const std::vector<float> zero(C, 0.f);
    const std::vector<std::int64_t> assists = {1, 2, 2, 0, 0, 1};
    ConditionOptions co;
    co.heads = heads;
    co.gate = 0.7;
    std::vector<float> out(x.size());
    avsplat::condition_tokens(x.data(), S, P, C, assists.data(), 2, w.view(), co, out.data());
    std::vector<float> keys(x.size()), values(x.size()), ref(x.size());
    for (int t = 0; t < S; ++t) {
        avsplat::assist_detail::project_rows<float>(x.data() + t * P * C, P, C, w.k.data(), zero.data(),
                                                    keys.data() + t * P * C);
        avsplat::assist_detail::project_rows<float>(x.data() + t * P * C, P, C, w.v.data(), zero.data(),
                                                    values.data() + t * P * C);
    }
    for (int s = 0; s < S; ++s) {
        const float* k[2] = {keys.data() + assists[2 * s] * P * C, keys.data() + assists[2 * s + 1] * P * C};
        const float* v[2] = {values.data() + assists[2 * s] * P * C, values.data() + assists[2 * s + 1] * P * C};
        avsplat::assist_detail::attend_rows<float>(x.data() + s * P * C, P, P, C, heads, 2, k, v, w.q.data(),
                                                   w.bq.data(), w.o.data(), w.bo.data(), 0.7, ref.data() + s * P * C);
    }
    double worst = 0;
    for (std::size_t i = 0; i < out.size(); ++i) worst = std::max(worst, double(std::abs(out[i] - ref[i])));
    CHECK(worst < 1e-5);
}
