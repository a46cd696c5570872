// decode_gaussians / encode_gaussians against hand-computed activations, and the simulator's
// private rank statistics (Spearman's rho, the confidence of a given rho) against hand-computed
// cases.
#include "avsplat/fusion/feature_decoder.h"
#include "sim/footprint.h"
#include "sim/prediction_errors.h"
#include "sim/random.h"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

using avsplat::FeatureLayout;

TEST_CASE("decode_gaussians applies AnySplat's activations", "[decoder]") {
    const FeatureLayout layout;  // opacity | log scale x3 | quaternion | SH degree 0
    REQUIRE(layout.channels() == 11);
    const std::vector<float> pos = {1, 2, 3, -1, -2, -3};
    std::vector<float> f = {0.f, std::log(2.f), 0.f, std::log(0.5f), 2, 0, 0, 0, 0.1f, -0.2f, 0.3f,
                            std::log(3.f), 0, 0, 0, 0, 0, 0, -5, 7, 8, 9};
    const float conf[2] = {0.25f, -4.f};
    const avsplat::GaussianCloud g = avsplat::decode_gaussians(pos.data(), 2, f.data(), 11, layout, conf);
    REQUIRE(g.size() == 2);
    CHECK(g.opacities[0] == 0.5f);
    CHECK(g.opacities[1] == Approx(0.75f));  // sigmoid(log 3) = 3 / 4
    CHECK(g.scales[0] == Approx(2.f));
    CHECK(g.scales[1] == 1.f);
    CHECK(g.scales[2] == Approx(0.5f));
    CHECK(g.rotations[0] == 1.f);
    CHECK(g.rotations[4 + 3] == -1.f);  // (0, 0, 0, -5) normalised
    CHECK(g.sh[0] == 0.1f);
    CHECK(g.sh[5] == 9.f);
    CHECK(g.confidence[1] == -4.f);
    CHECK(g.means[5] == -3.f);

    // encode is the inverse.
    const std::vector<float> back = avsplat::encode_gaussians(g, layout);
    CHECK(back[0] == Approx(0.f).margin(1e-7));
    CHECK(back[1] == Approx(std::log(2.0)));
    CHECK(back[11 + 7] == -1.f);
}

TEST_CASE("decode_gaussians names the first bad sample", "[decoder]") {
    const FeatureLayout layout;
    std::vector<float> pos(9, 0.f), f(33, 0.f);
    for (int i = 0; i < 3; ++i) f[11 * i + 4] = 1.f;
    auto message = [&]() -> std::string {
        try {
            avsplat::decode_gaussians(pos.data(), 3, f.data(), 11, layout);
        } catch (const std::invalid_argument& e) {
            return e.what();
        }
        return "";
    };
    CHECK(message().empty());
    f[11 * 2 + 3] = 89.f;
    CHECK(message().find("features[2, 3]") != std::string::npos);
    f[11 * 1 + 4] = 0.f;
    CHECK(message().find("features[1, 4..7]") != std::string::npos);
    f[11 * 1 + 9] = std::numeric_limits<float>::quiet_NaN();
    CHECK(message().find("features[1, 9]") != std::string::npos);
    FeatureLayout overlap;
    overlap.sh = 6;
    CHECK_THROWS_AS(overlap.validate(), std::invalid_argument);
    CHECK_THROWS_AS(avsplat::decode_gaussians(pos.data(), 3, f.data(), 10, layout), std::invalid_argument);
}

TEST_CASE("the footprint kernel is the box convolved with a Gaussian", "[sim]") {
    const auto box = avsplat::sim::footprint_kernel(4, 0.0);
    CHECK(box.margin == 0);
    CHECK(box.weight == std::vector<double>(4, 1.0));
    const auto k = avsplat::sim::footprint_kernel(2, 1.0);
    REQUIRE(k.margin == 4);
    REQUIRE(k.weight.size() == 18u);
    // Symmetric, and sums (times the sample spacing 1/2) to about 1: the box's area.
    double sum = 0.0, second = 0.0;
    for (std::size_t j = 0; j < k.weight.size(); ++j) {
        CHECK(k.weight[j] == Approx(k.weight[k.weight.size() - 1 - j]));
        const double d = (double(j) - 8 + 0.5) / 2 - 0.5;
        sum += k.weight[j] / 2;
        second += k.weight[j] / 2 * d * d;
    }
    CHECK(sum == Approx(1.0).epsilon(1e-3));
    CHECK(second == Approx(1.0 / 12 + 1.0).epsilon(2e-2));  // variance of box (x) N(0, 1)
}

TEST_CASE("Spearman's rho and the confidence of a given rho", "[sim]") {
    using avsplat::sim::spearman;
    CHECK(spearman({1, 2, 3, 4}, {10, 20, 30, 40}) == Approx(1.0));
    CHECK(spearman({1, 2, 3, 4}, {4, 3, 2, 1}) == Approx(-1.0));
    // Hand-computed: ranks (0,1,2,3) and (1,0,3,2): d^2 sum 4, rho = 1 - 6 * 4 / (4 * 15) = 0.6.
    CHECK(spearman({1, 2, 3, 4}, {2, 1, 4, 3}) == Approx(0.6));
    // Ties take their mean rank: ranks (0.5, 0.5, 2) and (0, 1, 2): Pearson of the ranks.
    CHECK(spearman({1, 1, 2}, {1, 2, 3}) == Approx(std::sqrt(3.0) / 2));
    CHECK(std::isnan(spearman({1, 1, 1}, {1, 2, 3})));

    const std::size_t n = 20000;
    avsplat::sim::Rng rng(7);
    std::vector<double> values(n), score(n), noise(n);
    for (std::size_t i = 0; i < n; ++i) {
        values[i] = rng.normal();
        score[i] = rng.uniform();
        noise[i] = rng.normal();
    }
    for (double rho : {0.0, 0.5, 0.9, 1.0}) {
        const std::vector<double> c = avsplat::sim::confidence_by_rank(values, score, noise, rho);
        CHECK(spearman(c, score) == Approx(rho).margin(0.02));
        std::vector<double> a = c, b = values;
        std::sort(a.begin(), a.end());
        std::sort(b.begin(), b.end());
        CHECK(a == b);  // the same values, handed out differently
    }
}
