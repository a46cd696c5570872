// Raw Gaussian-head features of the simulated predictions, their noise where a model is unsure,
// and the confidence of a given informativeness (sim/simulator.h, "Head features").
#include "avsplat/core/sh.h"
#include "sim/prediction_errors.h"
#include "sim/random.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace avsplat::sim {

namespace {

// Stream tag of the feature noise, distinct from the other per-view streams.
constexpr std::uint64_t kFeatureStream = 0xFEA75E0ull;
// Draws per pixel: 3 colour, 1 opacity, 3 log-scale, 1 confidence copula; every pixel draws all,
// valid or not, so that one model's setting never shifts another's numbers.
constexpr int kDraws = 8;
// Noise std per unit attribute_noise and uncertainty: colour, opacity logit, log scale.
constexpr double kOpacityNoise = 5.0, kScaleNoise = 2.0;
// The errors that make one unit of total error: 1 % of the depth, a colour error of 0.05.
constexpr double kGeometricUnit = 0.01, kAppearanceUnit = 0.05;

}  // namespace

void head_features(Predictions& P, const SimulatorOptions& o, const std::vector<float>& depth,
                   const std::vector<float>& reference) {
    const std::size_t total = P.valid.size(), per_view = static_cast<std::size_t>(P.height) * P.width;
    const FeatureLayout layout;  // opacity logit | log scale x3 | quaternion | SH degree 0
    const std::size_t C = static_cast<std::size_t>(layout.channels());
    P.feature_layout = layout;
    P.features.assign(total * C, 0.f);
    P.appearance_error.assign(total, 0.f);

    // Valid pixels in pixel order: the rows of P.gaussians().
    std::vector<std::size_t> pixel;
    for (std::size_t k = 0; k < total; ++k)
        if (P.valid[k]) pixel.push_back(k);
    const std::size_t n = pixel.size();
    std::vector<float> F = encode_gaussians(P.gaussians(), layout);

    std::vector<double> draws(total * kDraws);
#pragma omp parallel for schedule(static)
    for (int s = 0; s < P.views; ++s) {
        Rng rng(splitmix64(o.seed ^ splitmix64(kFeatureStream + static_cast<std::uint64_t>(s))));
        for (std::size_t k = s * per_view; k < (s + 1) * per_view; ++k)
            for (int j = 0; j < kDraws; ++j) draws[k * kDraws + j] = rng.normal();
    }

    // Colour noise, then the appearance and total errors.
    const double a = o.attribute_noise;
    std::vector<double> score(n), noise(n), conf(n);
    for (std::size_t r = 0; r < n; ++r) {
        const std::size_t k = pixel[r];
        float* f = &F[r * C];
        const double u = P.uncertainty[k];
        double e_app = 0.0;
        for (int c = 0; c < 3; ++c) {
            if (a > 0.0) f[layout.sh + c] = static_cast<float>(f[layout.sh + c] + a * u * draws[k * kDraws + c] / sh::kC0);
            e_app += std::abs(sh::dc_to_color(double(f[layout.sh + c])) - reference[3 * k + c]);
        }
        e_app /= 3.0;
        P.appearance_error[k] = static_cast<float>(e_app);
        const double e_total = P.true_error[k] / (kGeometricUnit * depth[k]) + e_app / kAppearanceUnit;
        score[r] = -e_total;
        noise[r] = draws[k * kDraws + 7];
        conf[r] = P.confidence[k];
    }
    if (o.confidence_rho) {
        conf = confidence_by_rank(conf, score, noise, *o.confidence_rho);
        for (std::size_t r = 0; r < n; ++r) P.confidence[pixel[r]] = static_cast<float>(conf[r]);
    }
    P.confidence_spearman = spearman(conf, score);

    // The opacity logit is the confidence (the opacity of P.gaussians() is its sigmoid), then the
    // opacity and scale noise.
    for (std::size_t r = 0; r < n; ++r) {
        const std::size_t k = pixel[r];
        float* f = &F[r * C];
        const double u = P.uncertainty[k];
        f[layout.opacity] = P.confidence[k];
        if (a > 0.0) {
            f[layout.opacity] = static_cast<float>(f[layout.opacity] + kOpacityNoise * a * u * draws[k * kDraws + 3]);
            for (int c = 0; c < 3; ++c)
                f[layout.scale + c] = static_cast<float>(f[layout.scale + c] + kScaleNoise * a * u * draws[k * kDraws + 4 + c]);
        }
        std::copy_n(f, C, &P.features[k * C]);
    }
}

}  // namespace avsplat::sim
