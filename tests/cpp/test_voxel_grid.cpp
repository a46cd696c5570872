// SparseVoxelGrid against a brute-force grouping written here (std::map of std::round keys).
#include "avsplat/fusion/voxel_grid.h"

#include <catch2/catch.hpp>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <vector>

using avsplat::InvalidPolicy;
using avsplat::SparseVoxelGrid;
using Catch::Matchers::Contains;

namespace {

using Key = std::array<std::int32_t, 3>;

// The reference: key = std::round(double(p) / voxel), voxels ordered by std::map (lexicographic),
// samples of a voxel in increasing index. Samples with keep[i] == 0 are left out.
std::map<Key, std::vector<std::int32_t>> brute_force(const std::vector<float>& p, double voxel,
                                                     const std::vector<std::uint8_t>& keep = {}) {
    std::map<Key, std::vector<std::int32_t>> groups;
    for (std::size_t i = 0; i < p.size() / 3; ++i) {
        if (!keep.empty() && !keep[i]) continue;
        Key k;
        for (int a = 0; a < 3; ++a) k[a] = static_cast<std::int32_t>(std::round(double(p[3 * i + a]) / voxel));
        groups[k].push_back(static_cast<std::int32_t>(i));
    }
    return groups;
}

void check_against_reference(const SparseVoxelGrid& g, const std::map<Key, std::vector<std::int32_t>>& ref,
                             std::size_t n) {
    REQUIRE(g.num_voxels() == ref.size());
    REQUIRE(g.num_samples() == n);
    REQUIRE(g.voxel_offsets().size() == ref.size() + 1);
    CHECK(g.voxel_offsets().front() == 0);
    std::vector<std::int32_t> expected_voxel(n, -1);
    std::size_t v = 0, total = 0;
    for (const auto& [key, ids] : ref) {
        INFO("voxel " << v);
        for (int a = 0; a < 3; ++a) REQUIRE(g.voxel_coords()[3 * v + a] == key[a]);
        REQUIRE(g.occupancy(v) == std::int32_t(ids.size()));
        const auto b = g.sample_indices().begin() + g.voxel_offsets()[v];
        REQUIRE(std::vector<std::int32_t>(b, b + std::int64_t(ids.size())) == ids);
        for (auto i : ids) expected_voxel[std::size_t(i)] = std::int32_t(v);
        total += ids.size();
        ++v;
    }
    CHECK(g.voxel_offsets().back() == std::int64_t(total));
    CHECK(g.sample_voxel() == expected_voxel);
    CHECK(g.dropped() == n - total);
}

std::vector<float> random_points(std::size_t n, float lo, float hi, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(lo, hi);
    std::vector<float> p(3 * n);
    for (auto& x : p) x = u(rng);
    return p;
}

}  // namespace

TEST_CASE("voxel grid groups a hand-made point set", "[voxel_grid]") {
    // voxel 1: keys (0,0,0), (1,0,0), (0,0,0), (-1,2,0), (1,0,0)
    const std::vector<float> p = {0.1f, 0.2f, -0.3f, 0.9f, 0.f,  0.f, -0.4f, 0.4f, 0.4f,
                                  -1.f, 2.2f, 0.f,   1.4f, 0.1f, 0.f};
    const SparseVoxelGrid g(p.data(), 5, 1.0);
    REQUIRE(g.num_voxels() == 3);
    CHECK(g.voxel_coords() == std::vector<std::int32_t>{-1, 2, 0, 0, 0, 0, 1, 0, 0});
    CHECK(g.voxel_offsets() == std::vector<std::int64_t>{0, 1, 3, 5});
    CHECK(g.sample_indices() == std::vector<std::int32_t>{3, 0, 2, 1, 4});
    CHECK(g.sample_voxel() == std::vector<std::int32_t>{1, 2, 1, 0, 2});
    CHECK(g.occupancy() == std::vector<std::int32_t>{1, 2, 2});
    CHECK(g.max_occupancy() == 2);
    CHECK(g.dropped() == 0);
    CHECK(g.voxel_size() == 1.0);
}

TEST_CASE("voxel keys round half away from zero", "[voxel_grid]") {
    // 0.5 -> 1, -0.5 -> -1, 1.5 -> 2, 2.5 -> 3 (nearbyint would give 0, 0, 2, 2); just below a
    // half stays down.
    const std::vector<float> p = {0.5f, -0.5f, 2.5f, 1.5f, -2.5f, std::nextafter(0.5f, 0.f)};
    const SparseVoxelGrid g(p.data(), 2, 1.0);
    REQUIRE(g.num_voxels() == 2);
    CHECK(g.voxel_coords() == std::vector<std::int32_t>{1, -1, 3, 2, -3, 0});
}

TEST_CASE("voxel grid matches the brute-force grouping", "[voxel_grid]") {
    for (double voxel : {0.05, 0.3, 1e-3}) {
        const std::size_t n = 20000;
        const auto p = random_points(n, -2.f, 3.f, 7);
        INFO("voxel " << voxel);
        const SparseVoxelGrid g(p.data(), n, voxel);
        check_against_reference(g, brute_force(p, voxel), n);
    }
}

TEST_CASE("voxel grid matches the brute force on the large-input sort paths", "[voxel_grid]") {
    // Above 2^16 samples the sort takes one parallel pass on the top key digit and sorts each
    // bucket in cache; a bucket above 2^16 samples takes the parallel path again. Both here:
    // 300k spread samples, then 200k of them squeezed into one slab that shares the top digit.
    const std::size_t n = 300000;
    auto p = random_points(n, -1.f, 1.f, 23);
    for (int pass = 0; pass < 2; ++pass) {
        if (pass == 1)
            for (std::size_t i = 0; i < 200000; ++i) {
                p[3 * i] = 0.1f;                           // one x key
                p[3 * i + 1] = 0.5f + 0.01f * (p[3 * i + 1] * 0.5f);  // a few y keys
            }
        INFO("pass " << pass);
        const int threads = omp_get_max_threads();
        omp_set_num_threads(1);
        const SparseVoxelGrid one(p.data(), n, 0.01);
        omp_set_num_threads(std::max(2, threads));
        const SparseVoxelGrid two(p.data(), n, 0.01);
        omp_set_num_threads(threads);
        check_against_reference(two, brute_force(p, 0.01), n);
        CHECK(one.sample_indices() == two.sample_indices());
        CHECK(one.voxel_offsets() == two.voxel_offsets());
    }
}

TEST_CASE("voxel keys near half-way points match round(p / voxel) in double", "[voxel_grid]") {
    // Points at (k + 0.5) * voxel, and the floats next to them, for voxel sizes that are not
    // powers of two: p / voxel lands within rounding noise of a tie.
    std::vector<float> p;
    for (double voxel : {0.1, 0.03, 7.0 / 3.0}) {
        p.clear();
        for (int k = -3000; k < 3000; k += 7) {
            const float x = float((k + 0.5) * voxel);
            for (float v : {x, std::nextafter(x, -1e30f), std::nextafter(x, 1e30f)}) {
                p.push_back(v);
                p.push_back(-v);
                p.push_back(float(k) * 0.25f);
            }
        }
        INFO("voxel " << voxel);
        const SparseVoxelGrid g(p.data(), p.size() / 3, voxel);
        check_against_reference(g, brute_force(p, voxel), p.size() / 3);
    }
}

TEST_CASE("voxel grid with a key range too wide to pack uses the comparison sort", "[voxel_grid]") {
    // Keys spread over +-2e9 per axis need 32 bits each: 96 + index bits > 64.
    const std::size_t n = 3000;
    auto p = random_points(n, -2e9f, 2e9f, 3);
    for (std::size_t i = 0; i < 300; ++i)  // some shared voxels
        for (int a = 0; a < 3; ++a) p[3 * (i + 300) + a] = p[3 * i + a];
    const SparseVoxelGrid g(p.data(), n, 1.0);
    check_against_reference(g, brute_force(p, 1.0), n);
}

TEST_CASE("voxel grid is the same for any thread count and input permutation", "[voxel_grid]") {
    const std::size_t n = 50000;
    const auto p = random_points(n, -1.f, 1.f, 11);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const SparseVoxelGrid one(p.data(), n, 0.02);
    omp_set_num_threads(std::max(2, threads));
    const SparseVoxelGrid two(p.data(), n, 0.02);
    omp_set_num_threads(threads);
    CHECK(one.voxel_coords() == two.voxel_coords());
    CHECK(one.voxel_offsets() == two.voxel_offsets());
    CHECK(one.sample_indices() == two.sample_indices());
    CHECK(one.sample_voxel() == two.sample_voxel());

    std::vector<std::int32_t> perm(n);
    std::iota(perm.begin(), perm.end(), 0);
    std::shuffle(perm.begin(), perm.end(), std::mt19937(5));
    std::vector<float> q(3 * n);
    for (std::size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) q[3 * i + a] = p[3 * std::size_t(perm[i]) + a];
    const SparseVoxelGrid shuffled(q.data(), n, 0.02);
    CHECK(shuffled.voxel_coords() == one.voxel_coords());
    CHECK(shuffled.voxel_offsets() == one.voxel_offsets());
    for (std::size_t i = 0; i < n; ++i)  // sample i of q is sample perm[i] of p
        REQUIRE(shuffled.sample_voxel()[i] == one.sample_voxel()[std::size_t(perm[i])]);
}

TEST_CASE("voxel grid rejects keys that do not fit int32", "[voxel_grid]") {
    std::vector<float> p = {0.f, 0.f, 0.f, 1.f, 2.f, 3.f, 5.f, 1e7f, 0.f, 1e7f, 0.f, 0.f};
    CHECK_THROWS_WITH(SparseVoxelGrid(p.data(), 4, 1e-3),
                      Contains("positions[2, 1] = 10000000") && Contains("does not fit int32"));
    // Still an error when dropping invalid samples: a valid point must not vanish silently.
    CHECK_THROWS_AS(SparseVoxelGrid(p.data(), 4, 1e-3, InvalidPolicy::Drop), std::invalid_argument);
    // Negative side, and the largest key that fits.
    p = {-3e9f, 0.f, 0.f};
    CHECK_THROWS_WITH(SparseVoxelGrid(p.data(), 1, 1.0), Contains("positions[0, 0]"));
    p = {2147483520.f, -2147483648.f, 0.f};  // representable floats with keys inside int32
    const SparseVoxelGrid edge(p.data(), 1, 1.0);
    CHECK(edge.voxel_coords() == std::vector<std::int32_t>{2147483520, -2147483647 - 1, 0});
}

TEST_CASE("voxel grid raises on or drops non-finite positions", "[voxel_grid]") {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const std::vector<float> p = {0.f, 0.f, 0.f, 1.f, nan, 0.f, 0.2f, 0.f, 0.f, 3.f, 3.f, -inf};
    CHECK_THROWS_WITH(SparseVoxelGrid(p.data(), 4, 1.0), Contains("positions[1, 1]") && Contains("NaN or Inf"));
    const SparseVoxelGrid g(p.data(), 4, 1.0, InvalidPolicy::Drop);
    CHECK(g.dropped() == 2);
    CHECK(g.num_voxels() == 1);
    CHECK(g.sample_voxel() == std::vector<std::int32_t>{0, -1, 0, -1});
    CHECK(g.sample_indices() == std::vector<std::int32_t>{0, 2});
}

TEST_CASE("voxel grid leaves out samples whose keep flag is 0", "[voxel_grid]") {
    const std::size_t n = 5000;
    const auto p = random_points(n, -1.f, 1.f, 21);
    std::vector<std::uint8_t> keep(n);
    for (std::size_t i = 0; i < n; ++i) keep[i] = (i % 3) != 0;
    const SparseVoxelGrid g(p.data(), n, 0.1, InvalidPolicy::Raise, keep.data());
    check_against_reference(g, brute_force(p, 0.1, keep), n);
}

TEST_CASE("voxel grid edge cases", "[voxel_grid]") {
    const SparseVoxelGrid empty(nullptr, 0, 0.1);
    CHECK(empty.num_voxels() == 0);
    CHECK(empty.voxel_offsets() == std::vector<std::int64_t>{0});
    CHECK(empty.max_occupancy() == 0);
    const std::vector<float> p = {1.f, 2.f, 3.f};
    for (double bad : {0.0, -1.0, std::numeric_limits<double>::infinity(), std::nan("")})
        CHECK_THROWS_WITH(SparseVoxelGrid(p.data(), 1, bad), Contains("voxel_size"));
    const SparseVoxelGrid one(p.data(), 1, 0.5);
    CHECK(one.voxel_coords() == std::vector<std::int32_t>{2, 4, 6});
    // A million samples in one voxel.
    const std::size_t n = 1000000;
    std::vector<float> same(3 * n, 0.25f);
    const SparseVoxelGrid big(same.data(), n, 1.0);
    CHECK(big.num_voxels() == 1);
    CHECK(big.occupancy(0) == std::int32_t(n));
    CHECK(big.max_occupancy() == std::int32_t(n));
    CHECK(std::is_sorted(big.sample_indices().begin(), big.sample_indices().end()));
}
