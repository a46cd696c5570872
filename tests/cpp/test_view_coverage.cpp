#include "avsplat/assist/view_coverage.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <stdexcept>
#include <vector>

using avsplat::ViewCoverageOptions;

namespace {
// S views of 3 points on the x axis; voxel 1 makes voxel k the points with x = k.
std::vector<float> on_x_axis(const std::vector<std::vector<float>>& xs) {
    std::vector<float> p;
    for (const auto& view : xs)
        for (float x : view) p.insert(p.end(), {x, 0.f, 0.f});
    return p;
}
}  // namespace

TEST_CASE("view coverage: hand-computed greedy order, gains and budget", "[view_coverage]") {
    // View 0 covers {0, 1, 2}, view 1 {2, 3}, view 2 {4}, view 3 {0, 1}.
    const auto p = on_x_axis({{0, 1, 2}, {2, 3, 3}, {4, 4, 4}, {0, 1, 1}});
    ViewCoverageOptions o;
    o.voxel_size = 1.0;
    auto r = avsplat::select_views_by_coverage(p.data(), nullptr, nullptr, 4, 1, 3, o);
    CHECK(r.order == std::vector<std::int64_t>{0, 1, 2, 3});
    CHECK(r.gains == std::vector<std::int64_t>{3, 1, 1, 0});
    CHECK(r.coverage == std::vector<std::int64_t>{3, 4, 5, 5});
    CHECK(r.total_voxels == 5);

    o.budget = 2;
    r = avsplat::select_views_by_coverage(p.data(), nullptr, nullptr, 4, 1, 3, o);
    CHECK(r.order == std::vector<std::int64_t>{0, 1});
    o.budget = 0;
    o.min_gain = 0.25;  // 1.25 voxels: views adding one voxel stop the selection
    r = avsplat::select_views_by_coverage(p.data(), nullptr, nullptr, 4, 1, 3, o);
    CHECK(r.order == std::vector<std::int64_t>{0});
}

TEST_CASE("view coverage: confidence and validity leave pixels out; bad input is named", "[view_coverage]") {
    auto p = on_x_axis({{0, 1, 2}, {5, 6, 7}});
    const std::vector<float> conf = {1, 1, 1, 1, 0, 0};      // view 1 keeps only x = 5
    const std::vector<std::uint8_t> valid = {1, 1, 0, 1, 1, 1};  // view 0 loses x = 2
    ViewCoverageOptions o;
    o.voxel_size = 1.0;
    o.min_confidence = 0.5;
    auto r = avsplat::select_views_by_coverage(p.data(), conf.data(), valid.data(), 2, 1, 3, o);
    CHECK(r.order == std::vector<std::int64_t>{0, 1});
    CHECK(r.gains == std::vector<std::int64_t>{2, 1});
    CHECK(r.points_used == 3);

    p[3 * 4 + 1] = std::nanf("");
    CHECK_THROWS_WITH(avsplat::select_views_by_coverage(p.data(), nullptr, nullptr, 2, 1, 3, o),
                      Catch::Contains("points[1, 0, 1, 1] = nan"));
    o.voxel_size = -1;
    CHECK_THROWS_AS(avsplat::select_views_by_coverage(p.data(), nullptr, nullptr, 2, 1, 3, o), std::invalid_argument);
}
