// weighted_rows (lib/src/fusion/weighted_rows.h), the averaging step of both fusion entry points,
// against a long-double reference, for widths that take every block path (32, 16, 8 and 4
// channels at a time, then single channels) and for the finiteness flag at every channel; the
// AVX2 and baseline versions against each other, bit for bit.
#include "fusion/weighted_rows.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

using avsplat::fusion_detail::weighted_rows;

namespace {

// The distance from float(x) to the next float away from zero: the rounding step at x.
double float_step(double x) {
    const float f = float(x);
    return std::abs(double(std::nextafter(f, f < 0 ? -INFINITY : INFINITY)) - double(f));
}

// n random rows of `rows` and their weights; returns 1 / (the sum of the weights).
double random_samples(std::mt19937& rng, std::size_t rows, std::size_t n, std::vector<std::int32_t>& ids,
                      std::vector<double>& w) {
    std::uniform_real_distribution<double> weight(0.0, 1.0);
    ids.resize(n);
    w.resize(n);
    double wsum = 0.0;
    for (std::size_t k = 0; k < n; ++k) {
        ids[k] = std::int32_t(rng() % rows);
        w[k] = weight(rng);
        wsum += w[k];
    }
    return 1.0 / wsum;
}

}  // namespace

TEST_CASE("weighted_rows matches a long-double reference for every width", "[fusion]") {
    std::mt19937 rng(18);
    std::uniform_real_distribution<float> value(-3.f, 3.f);
    const std::size_t rows = 300;
    for (const std::size_t width : {1, 2, 3, 4, 5, 7, 8, 9, 12, 15, 16, 17, 24, 28, 31, 32, 33, 37, 44, 48, 56, 60, 63,
                                    64, 65, 100}) {
        std::vector<float> data(rows * width);
        for (float& x : data) x = value(rng);
        for (const std::size_t n : {1, 2, 9, 40}) {
            std::vector<std::int32_t> ids;
            std::vector<double> w;
            const double inv = random_samples(rng, rows, n, ids, w);
            std::vector<float> out(width + 1, -7.f);
            REQUIRE(weighted_rows(data.data(), width, ids.data(), w.data(), n, inv, out.data()));
            CHECK(out[width] == -7.f);  // nothing written past the row
            for (std::size_t c = 0; c < width; ++c) {
                long double ref = 0.0L;
                for (std::size_t k = 0; k < n; ++k) ref += (long double)w[k] * data[width * std::size_t(ids[k]) + c];
                const double expected = double(ref * (long double)inv);
                INFO("width " << width << ", n " << n << ", channel " << c);
                // One rounding to float, plus the double sums' error (far below it).
                REQUIRE(std::abs(double(out[c]) - expected) <= float_step(expected) + 1e-12);
            }
        }
    }
}

TEST_CASE("weighted_rows reports a non-finite value in any channel", "[fusion]") {
    const float bad[] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                         -std::numeric_limits<float>::infinity()};
    for (const std::size_t width : {1, 5, 16, 37, 56}) {
        for (std::size_t c = 0; c < width; ++c) {
            for (const float b : bad) {
                std::vector<float> data(4 * width, 0.5f);
                data[2 * width + c] = b;  // row 2
                const std::int32_t ids[] = {0, 2, 3};
                const double w[] = {0.5, 0.0, 0.5};  // a zero weight still carries NaN/Inf into the sum
                std::vector<float> out(width);
                INFO("width " << width << ", channel " << c << ", value " << b);
                REQUIRE_FALSE(weighted_rows(data.data(), width, ids, w, 3, 1.0, out.data()));
                for (std::size_t d = 0; d < width; ++d)
                    if (d != c) REQUIRE(out[d] == 0.5f);
            }
        }
    }
    // Finite inputs whose weighted sum overflows float32 are reported too.
    std::vector<float> big(8, 3e38f);
    const std::int32_t ids[] = {0};
    const double w[] = {4.0};
    std::vector<float> out(8);
    REQUIRE_FALSE(weighted_rows(big.data(), 8, ids, w, 1, 1.0, out.data()));
}

TEST_CASE("weighted_rows: the AVX2 and baseline versions give the same bits", "[fusion]") {
    using avsplat::fusion_detail::weighted_rows_avx2;
    using avsplat::fusion_detail::weighted_rows_baseline;
    if (!avsplat::fusion_detail::avx2_available()) {
        WARN("no AVX2 on this CPU: only the baseline version runs");
        return;
    }
    std::mt19937 rng(6);
    std::uniform_real_distribution<float> value(-3e3f, 3e3f);
    const std::size_t rows = 200;
    for (std::size_t width = 1; width <= 120; ++width) {
        std::vector<float> data(rows * width + 1);
        for (float& x : data) x = value(rng);
        // Rows starting 4 bytes into the allocation: the loads are unaligned, as numpy's rows are.
        const float* base = data.data() + 1;
        for (const std::size_t n : {1, 2, 5, 9, 33}) {
            std::vector<std::int32_t> ids;
            std::vector<double> w;
            const double inv = random_samples(rng, rows, n, ids, w);
            std::vector<float> a(width + 1, -7.f), b(width + 1, -9.f);
            const bool ok_a = weighted_rows_avx2(base, width, ids.data(), w.data(), n, inv, a.data());
            const bool ok_b = weighted_rows_baseline(base, width, ids.data(), w.data(), n, inv, b.data());
            INFO("width " << width << ", n " << n);
            REQUIRE(ok_a == ok_b);
            CHECK(a[width] == -7.f);
            for (std::size_t c = 0; c < width; ++c) {
                std::uint32_t ua, ub;
                std::memcpy(&ua, &a[c], sizeof ua);
                std::memcpy(&ub, &b[c], sizeof ub);
                REQUIRE(ua == ub);
            }
        }
    }
    // The finiteness flag agrees too, for each bad value in each channel.
    for (const std::size_t width : {4, 13, 56}) {
        for (std::size_t c = 0; c < width; ++c) {
            std::vector<float> data(2 * width, 1.f);
            data[width + c] = std::numeric_limits<float>::infinity();
            const std::int32_t ids[] = {0, 1};
            const double w[] = {0.5, 0.5};
            std::vector<float> out(width);
            REQUIRE_FALSE(weighted_rows_avx2(data.data(), width, ids, w, 2, 1.0, out.data()));
            REQUIRE_FALSE(weighted_rows_baseline(data.data(), width, ids, w, 2, 1.0, out.data()));
        }
    }
}
