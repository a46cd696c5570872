// The private helpers of lib/src/common and lib/src/core shared by fusion, the grid and the
// renderers, each held to a brute-force reference.
#include "common/order_key.h"
#include "common/parallel_compact.h"
#include "common/radix_sort.h"
#include "common/rank16.h"
#include "core/gaussian_validity.h"
#include "core/invalid_samples.h"

#include <catch2/catch.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

using namespace avsplat;

namespace {

std::vector<float> awkward_floats() {
    const float inf = std::numeric_limits<float>::infinity();
    std::vector<float> v = {-inf, -3.5f, -1e-40f, -0.f, 0.f, 1e-40f, 1.f, 2.5f, 1e30f, inf,
                            std::numeric_limits<float>::denorm_min(), -std::numeric_limits<float>::max()};
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-10.f, 10.f);
    for (int i = 0; i < 40; ++i) v.push_back(u(rng));
    return v;
}

}  // namespace

TEST_CASE("float_order_key orders like the floats; the descending key reverses it", "[common]") {
    const std::vector<float> v = awkward_floats();
    for (float a : v) {
        for (float b : v) {
            if (a < b) {
                CHECK(float_order_key(a) < float_order_key(b));
                CHECK(float_descending_key(a) > float_descending_key(b));
            }
        }
        CHECK(float_descending_key(a) != ~std::uint32_t(0));
        CHECK(float_order_key(a) != 0u);
    }
    // -0 sorts just before +0 (different bits, adjacent keys).
    CHECK(float_order_key(-0.f) + 1 == float_order_key(0.f));
}

TEST_CASE("rank16: counting ranks equal a stable sort's places", "[common]") {
    std::mt19937 rng(11);
    for (int trial = 0; trial < 200; ++trial) {
        const int n = 1 + int(rng() % 16);
        // Few distinct values, so that ties are common.
        std::uniform_int_distribution<int> pick(0, 4);
        float c[16];
        std::uint32_t x[16];
        for (int i = 0; i < 16; ++i) {
            c[i] = i < n ? float(pick(rng)) - 1.5f : -std::numeric_limits<float>::infinity();
            x[i] = i < n ? std::uint32_t(pick(rng)) * 0x40000000u : ~std::uint32_t(0);
        }
        std::vector<int> by_desc(n), by_asc(n);
        for (int i = 0; i < n; ++i) by_desc[i] = by_asc[i] = i;
        std::stable_sort(by_desc.begin(), by_desc.end(), [&](int a, int b) { return c[a] > c[b]; });
        std::stable_sort(by_asc.begin(), by_asc.end(), [&](int a, int b) { return x[a] < x[b]; });
        int rank_desc[16], rank_asc[16];
        rank_descending16(c, n, rank_desc);
        rank_ascending16(x, n, rank_asc);
        for (int k = 0; k < n; ++k) {
            CHECK(rank_desc[by_desc[k]] == k);
            CHECK(rank_asc[by_asc[k]] == k);
        }
        // The double path (plain loop) agrees with the float one.
        double cd[16];
        for (int i = 0; i < 16; ++i) cd[i] = double(c[i]);
        int rank_d[16];
        rank_descending16(cd, n, rank_d);
        for (int i = 0; i < n; ++i) CHECK(rank_d[i] == rank_desc[i]);
    }
}

TEST_CASE("radix_sort equals a stable sort on the key bits, for any thread count", "[common]") {
    std::mt19937_64 rng(3);
    for (const std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(1000), std::size_t(1) << 17}) {
        for (const auto& bits : {std::pair<int, int>{0, 9}, {20, 64}, {3, 40}}) {
            std::vector<std::uint64_t> a(n);
            // Bits from hi_bit on are zero (the contract); some digits repeat.
            const std::uint64_t below_hi = bits.second >= 64 ? ~0ull : (1ull << bits.second) - 1;
            for (auto& k : a) k = rng() & (rng() % 2 ? ~0ull : 0xFFFF0000FFFFull) & below_hi;
            const auto key = [&](std::uint64_t k) { return k >> bits.first; };
            std::vector<std::uint64_t> want = a;
            std::stable_sort(want.begin(), want.end(), [&](std::uint64_t x, std::uint64_t y) { return key(x) < key(y); });
            for (const int threads : {1, 2, 3}) {
                omp_set_num_threads(threads);
                std::vector<std::uint64_t> b = a, tmp(n);
                const std::uint64_t* r = radix_sort(b.data(), tmp.data(), n, bits.first, bits.second);
                CHECK(std::equal(want.begin(), want.end(), r));
            }
        }
    }
    omp_set_num_threads(omp_get_num_procs());
}

TEST_CASE("parallel_compact equals std::copy_if, for any thread count", "[common]") {
    std::mt19937_64 rng(5);
    for (const std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(1000), std::size_t(1) << 17}) {
        for (const unsigned every : {1u, 3u, 1000000u}) {  // keep all, about a third, almost none
            std::vector<std::uint64_t> a(n);
            for (auto& v : a) v = rng();
            const auto keep = [every](std::uint64_t v) { return v % every == 0; };
            std::vector<std::uint64_t> want;
            std::copy_if(a.begin(), a.end(), std::back_inserter(want), keep);
            for (const int threads : {1, 2, 3}) {
                omp_set_num_threads(threads);
                std::vector<std::uint64_t> out(n, 0);
                const std::size_t count = parallel_compact(a.data(), n, out.data(), keep);
                REQUIRE(count == want.size());
                CHECK(std::equal(want.begin(), want.end(), out.begin()));
            }
        }
    }
    omp_set_num_threads(omp_get_num_procs());
}

TEST_CASE("radix_sort of records (the renderer's depth sort) equals a stable sort on the key bits", "[common]") {
    // Records as the CPU renderer sorts them: a depth key in the upper word, the index in the
    // lower word, and a payload that must travel with its key.
    struct Item {
        std::uint64_t key;
        std::int32_t payload[3];
    };
    std::mt19937_64 rng(5);
    for (const std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(777), std::size_t(1) << 17}) {
        std::vector<Item> a(n);
        for (std::size_t i = 0; i < n; ++i) {
            // Few distinct depths (ties are common in a render), index in the low word.
            const std::uint64_t depth = rng() % 2 ? rng() % 64 : rng() >> 32;
            a[i] = {(depth << 32) | i, {std::int32_t(i), -std::int32_t(i), std::int32_t(depth % 1000)}};
        }
        std::shuffle(a.begin(), a.end(), rng);
        std::vector<Item> want = a;
        std::stable_sort(want.begin(), want.end(), [](const Item& x, const Item& y) { return (x.key >> 32) < (y.key >> 32); });
        for (const int threads : {1, 2, 3}) {
            omp_set_num_threads(threads);
            std::vector<Item> b = a, tmp(n);
            const Item* r = radix_sort(b.data(), tmp.data(), n, 32, 64, [](const Item& it) { return it.key; });
            bool same = true;
            for (std::size_t i = 0; i < n && same; ++i)
                same = r[i].key == want[i].key && r[i].payload[0] == want[i].payload[0] &&
                       r[i].payload[1] == want[i].payload[1] && r[i].payload[2] == want[i].payload[2];
            CHECK(same);
        }
    }
    omp_set_num_threads(omp_get_num_procs());
}

TEST_CASE("apply_invalid_policy: first bad index, then raise or drop", "[common]") {
    const std::size_t n = 50000;  // above kParallelMin: the parallel search
    std::vector<int> bad_at(n, 0);
    for (std::size_t i : {std::size_t(40000), std::size_t(17), std::size_t(33333)}) bad_at[i] = 1;
    const auto bad = [&](std::size_t i) { return bad_at[i] != 0; };
    for (const int threads : {1, 2, 4}) {
        omp_set_num_threads(threads);
        CHECK(first_bad_index(n, bad) == 17);
        std::vector<std::uint8_t> keep;
        std::size_t raised = kNoIndex;
        CHECK_THROWS_AS(apply_invalid_policy(n, bad, InvalidPolicy::Raise, keep,
                                             [&](std::size_t i) {
                                                 raised = i;
                                                 throw std::invalid_argument("bad");
                                             }),
                        std::invalid_argument);
        CHECK(raised == 17);
        CHECK(keep.empty());
        CHECK(apply_invalid_policy(n, bad, InvalidPolicy::Drop, keep, [](std::size_t) {}));
        REQUIRE(keep.size() == n);
        for (std::size_t i = 0; i < n; ++i) REQUIRE(int(keep[i]) == 1 - bad_at[i]);
    }
    omp_set_num_threads(omp_get_num_procs());
    std::vector<std::uint8_t> keep;
    CHECK_FALSE(apply_invalid_policy(n, [](std::size_t) { return false; }, InvalidPolicy::Drop, keep,
                                     [](std::size_t) {}));
    CHECK(keep.empty());
    CHECK(first_bad_index(0, bad) == kNoIndex);
}

TEST_CASE("check_gaussian: defects and fields in the documented order", "[common]") {
    const float nan = std::nanf(""), inf = std::numeric_limits<float>::infinity();
    float mean[3] = {0.f, 1.f, 2.f}, scale[3] = {1.f, 1.f, 1.f}, quat[4] = {1.f, 0.f, 0.f, 0.f}, sh[3] = {0.f, 0.f, 0.f};
    GaussianField f = GaussianField::Means;
    CHECK(check_gaussian(mean, scale, quat, 0.5f, sh, 3, f) == GaussianDefect::None);
    // A non-finite value wins over a range defect, and the first non-finite field is named.
    scale[0] = -1.f;
    sh[2] = inf;
    CHECK(check_gaussian(mean, scale, quat, 2.f, sh, 3, f) == GaussianDefect::NonFinite);
    CHECK(f == GaussianField::Sh);
    quat[3] = nan;
    CHECK(check_gaussian(mean, scale, quat, 2.f, sh, 3, f) == GaussianDefect::NonFinite);
    CHECK(f == GaussianField::Rotations);
    quat[3] = 0.f;
    sh[2] = 0.f;
    CHECK(check_gaussian(mean, scale, quat, 2.f, sh, 3, f) == GaussianDefect::NegativeScale);
    CHECK(f == GaussianField::Scales);
    scale[0] = 0.f;  // zero scales are valid
    quat[0] = 0.f;
    CHECK(check_gaussian(mean, scale, quat, 2.f, sh, 3, f) == GaussianDefect::ZeroRotation);
    CHECK(f == GaussianField::Rotations);
    quat[0] = -0.5f;
    CHECK(check_gaussian(mean, scale, quat, 2.f, sh, 3, f) == GaussianDefect::OpacityRange);
    CHECK(f == GaussianField::Opacities);
    CHECK(check_gaussian(mean, scale, quat, 1.f, sh, 3, f) == GaussianDefect::None);

    // The cloud form adds the confidence and the extras, after the core fields.
    GaussianCloud c(2, 0);
    c.opacities = {0.5f, 0.5f};
    c.sh.assign(6, 0.f);
    c.rotations = {1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f};
    c.confidence = {1.f, inf};
    c.extras.push_back({"e", {nan, 0.f}});
    CHECK(check_gaussian(c, 0, f) == GaussianDefect::NonFinite);
    CHECK(f == GaussianField::Extras);
    CHECK(check_gaussian(c, 1, f) == GaussianDefect::NonFinite);
    CHECK(f == GaussianField::Confidence);
    c.means[3] = nan;
    CHECK(check_gaussian(c, 1, f) == GaussianDefect::NonFinite);
    CHECK(f == GaussianField::Means);
    CHECK(std::string(gaussian_field_name(GaussianField::Confidence)) == "confidence");
}
