// AllKnnTree (common/all_knn.h), simplify's neighbour search, against a brute force written
// here: exact lists, ties by the nearer index, on uniform, surface, grid and doubled points.
#include "common/all_knn.h"

#include <catch2/catch.hpp>
#include <Eigen/Core>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <random>
#include <stdexcept>
#include <tuple>
#include <vector>


namespace {

// The k nearest others of point i by brute force: (squared distance in double, index), smallest
// first, as a sorted list of indices.
std::vector<std::uint32_t> knn_ref(const std::vector<float>& p, std::size_t i, std::size_t k) {
    const std::size_t n = p.size() / 3;
    std::vector<std::pair<double, std::uint32_t>> d;
    for (std::size_t j = 0; j < n; ++j) {
        if (j == i) continue;
        double s = 0.0;
        for (int a = 0; a < 3; ++a) {
            const double x = double(p[3 * j + a]) - double(p[3 * i + a]);
            s += x * x;
        }
        d.emplace_back(s, std::uint32_t(j));
    }
    k = std::min(k, d.size());
    // Ties by the nearer index, then the smaller.
    auto gap = [i](std::uint32_t j) { return j > i ? j - i : i - j; };
    std::partial_sort(d.begin(), d.begin() + std::ptrdiff_t(k), d.end(), [&](const auto& x, const auto& y) {
        return std::make_tuple(x.first, gap(x.second), x.second) < std::make_tuple(y.first, gap(y.second), y.second);
    });
    std::vector<std::uint32_t> out;
    for (std::size_t t = 0; t < k; ++t) out.push_back(d[t].second);
    std::sort(out.begin(), out.end());
    return out;
}

void check_all_knn(const std::vector<float>& p, std::size_t k) {
    const std::size_t n = p.size() / 3;
    const avsplat::detail::AllKnnTree tree(p.data(), n, "test");
    const std::size_t kk = std::min(k, n - 1);
    std::vector<std::uint32_t> out(n * kk, 0xffffffffu);
    for (std::size_t l = 0; l < tree.leaf_count(); ++l) tree.all_knn_leaf(l, k, out.data());
    for (std::size_t i = 0; i < n; ++i) {
        std::vector<std::uint32_t> got(out.begin() + std::ptrdiff_t(i * kk), out.begin() + std::ptrdiff_t((i + 1) * kk));
        std::sort(got.begin(), got.end());
        INFO("n " << n << ", k " << k << ", point " << i);
        REQUIRE(got == knn_ref(p, i, k));
    }
}

}  // namespace

TEST_CASE("simplify: the all-kNN tree finds the brute-force neighbours, ties by index", "[simplify]") {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    std::normal_distribution<float> nrm(0.f, 1.f);
    for (std::size_t n : {1u, 2u, 3u, 16u, 17u, 33u, 500u, 3000u}) {
        // Uniform in a cube; on a surface (a sphere: flat neighbourhoods, like a scene); on a
        // grid (equal distances everywhere, decided by index); with every point doubled.
        std::vector<float> cube(3 * n), sphere(3 * n), grid(3 * n), twice(3 * n);
        for (std::size_t i = 0; i < n; ++i) {
            Eigen::Vector3f v(nrm(rng), nrm(rng), nrm(rng));
            v.normalize();
            for (int a = 0; a < 3; ++a) {
                cube[3 * i + a] = u(rng);
                sphere[3 * i + a] = v[a];
                grid[3 * i + a] = float(int(8.f * (u(rng) + 1.f)));
                twice[3 * i + a] = cube[3 * (i / 2) + a];
            }
        }
        for (std::size_t k : {1u, 4u, 16u, 32u}) {
            check_all_knn(cube, k);
            check_all_knn(sphere, k);
            check_all_knn(grid, k);
            check_all_knn(twice, k);
        }
    }
    // All points equal: the k smallest other indices. One point: nothing to find.
    check_all_knn(std::vector<float>(3 * 100, 0.25f), 16);
    check_all_knn(std::vector<float>(3 * 3000, 0.25f), 16);
    {
        // Many equal points: a leaf whose index range cannot beat a query's k-th is skipped, so
        // this is linear (it visited every leaf from every leaf before: 10^10 distances, tens
        // of seconds). Each point's neighbours are the 16 nearest other indices.
        const std::size_t n = 100000;
        const std::vector<float> same(3 * n, -3.5f);
        const avsplat::detail::AllKnnTree tree(same.data(), n, "test");
        std::vector<std::uint32_t> out(n * 16);
        for (std::size_t l = 0; l < tree.leaf_count(); ++l) tree.all_knn_leaf(l, 16, out.data());
        for (std::size_t i = 0; i < n; i += 997) {
            std::vector<std::uint32_t> got(out.begin() + std::ptrdiff_t(i * 16), out.begin() + std::ptrdiff_t(i * 16 + 16));
            std::sort(got.begin(), got.end());
            std::vector<std::uint32_t> all(n);
            std::iota(all.begin(), all.end(), std::uint32_t(0));
            auto gap = [i](std::uint32_t j) { return j > i ? j - i : std::uint32_t(i) - j; };
            std::partial_sort(all.begin(), all.begin() + 17, all.end(), [&](std::uint32_t x, std::uint32_t y) {
                return std::make_pair(gap(x), x) < std::make_pair(gap(y), y);
            });
            std::vector<std::uint32_t> want(all.begin() + 1, all.begin() + 17);  // all[0] is i
            std::sort(want.begin(), want.end());
            REQUIRE(got == want);
        }
    }
    const std::vector<float> one{1.f, 2.f, 3.f};
    const avsplat::detail::AllKnnTree single(one.data(), 1, "test");
    REQUIRE(single.leaf_count() == 1);
    single.all_knn_leaf(0, 16, nullptr);  // k = min(16, n - 1) = 0: writes nothing
    std::vector<std::uint32_t> out(16 * 40);
    REQUIRE_THROWS_AS(avsplat::detail::AllKnnTree(one.data(), 1, "test").all_knn_leaf(0, 33, out.data()),
                      std::invalid_argument);
}

TEST_CASE("simplify: the all-kNN tree's split puts the smallest keys first", "[simplify]") {
    // The tree's shape comes from this split, but the lists do not (any partition gives the
    // exact neighbours, only slower), so the test above cannot see a wrong split: here against
    // a full sort by (coordinate, index), -0 before +0, on orders that defeat simple pivots, and
    // through the std::nth_element fallback (max_rounds 0 and 1).
    using P = avsplat::detail::AllKnnTree::BuildPoint;
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    auto key = [](const P& p, int axis) {
        float c = p.c[axis];
        std::uint32_t b;
        std::memcpy(&b, &c, sizeof b);
        b = (b & 0x80000000u) ? ~b : (b | 0x80000000u);
        return (std::uint64_t(b) << 32) | p.id;
    };
    for (std::size_t n : {17u, 18u, 33u, 100u, 1000u, 20000u}) {
        for (int shape = 0; shape < 6; ++shape) {
            std::vector<P> pts(n);
            for (std::size_t i = 0; i < n; ++i) {
                float v = u(rng);
                if (shape == 1) v = float(i);                                   // sorted
                if (shape == 2) v = -float(i);                                  // reversed
                if (shape == 3) v = float(std::min(i, n - 1 - i));              // organ pipe
                if (shape == 4) v = 0.5f;                                       // equal: by index
                if (shape == 5) v = (i % 3 == 0) ? -0.f : (i % 3 == 1 ? 0.f : u(rng));  // signed zeros
                pts[i] = P{{u(rng), v, u(rng)}, std::uint32_t(i)};
            }
            for (int max_rounds : {64, 1, 0}) {
                for (std::size_t mid : {std::size_t(1), n / 2, n - 1}) {
                    std::vector<P> a = pts;
                    avsplat::detail::AllKnnTree::split(a.data(), 0, mid, n, 1, max_rounds);
                    std::vector<std::uint64_t> want, got_left, got_right;
                    for (const P& p : pts) want.push_back(key(p, 1));
                    std::sort(want.begin(), want.end());
                    for (std::size_t i = 0; i < n; ++i) (i < mid ? got_left : got_right).push_back(key(a[i], 1));
                    std::sort(got_left.begin(), got_left.end());
                    std::sort(got_right.begin(), got_right.end());
                    INFO("n " << n << ", shape " << shape << ", max_rounds " << max_rounds << ", mid " << mid);
                    REQUIRE(got_left == std::vector<std::uint64_t>(want.begin(), want.begin() + std::ptrdiff_t(mid)));
                    REQUIRE(got_right == std::vector<std::uint64_t>(want.begin() + std::ptrdiff_t(mid), want.end()));
                    // The points themselves are moved whole: each id keeps its coordinates.
                    for (const P& p : a) REQUIRE(std::memcmp(p.c, pts[p.id].c, sizeof p.c) == 0);
                }
            }
        }
    }
}
