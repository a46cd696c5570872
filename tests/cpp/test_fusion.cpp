// Voxel fusion against a float64 brute-force reference written here: std::map grouping, plain
// loops, std::sort-based sparsemax and trimming, independent of lib/ except for the parameter
// struct. Plus the stiff cases, the invariants and the header-only weight primitives.
#include "avsplat/fusion/fusion.h"
#include "fusion/voxel_weights.h"
#include "reference/voxel_weights_reference.h"

#include <catch2/catch.hpp>
#include <omp.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <vector>

using namespace avsplat;
using Catch::Matchers::Contains;

namespace {

using Key = std::array<std::int32_t, 3>;

struct Inputs {
    std::size_t n = 0;
    int channels = 0;
    std::vector<float> positions, features, confidence;  // confidence empty: absent
    const float* conf() const { return confidence.empty() ? nullptr : confidence.data(); }
};

// ---------------------------------------------------------------------------------------------
// The reference

struct Reference {
    std::vector<Key> keys;
    std::vector<double> positions, features, temperature, variance, reliability, entropy;
    std::vector<int> occupancy;
    // Non-zero weights: the float32 path may underflow weights below ~1e-38 to 0, so a result
    // must lie between the count of weights > 1e-36 and the count of weights > 0.
    std::vector<int> kept_min, kept;
    std::vector<std::vector<double>> weights;  // per voxel, in input order of its samples
    std::vector<std::vector<int>> members;
};

double ref_probability(double c, ConfidenceMapping m) {
    if (m == ConfidenceMapping::Probability) return c;
    if (m == ConfidenceMapping::Positive) return c / (1.0 + c);
    return 1.0 / (1.0 + std::exp(-c));
}

double ref_logit(double c, ConfidenceMapping m) {
    double l = c;
    if (m == ConfidenceMapping::Probability) l = std::log(c / (1.0 - c));
    if (m == ConfidenceMapping::Positive) l = std::log(c);
    return std::min(std::max(l, -double(FLT_MAX)), double(FLT_MAX));
}

std::vector<double> ref_softmax(const std::vector<double>& z) {
    const double mx = *std::max_element(z.begin(), z.end());
    std::vector<double> w(z.size());
    double s = 0;
    for (std::size_t i = 0; i < z.size(); ++i) s += (w[i] = std::exp(z[i] - mx));
    for (auto& x : w) x /= s;
    return w;
}

std::vector<double> ref_sparsemax(std::vector<double> z) {
    // Shift-invariant; shifting keeps 1 + k z > sum meaningful for logits of 1e30.
    const double mx = *std::max_element(z.begin(), z.end());
    for (auto& x : z) x -= mx;
    std::vector<double> s = z;
    std::sort(s.rbegin(), s.rend());
    double cum = 0, tau = 0;
    for (std::size_t k = 0; k < s.size(); ++k) {
        cum += s[k];
        if (1.0 + double(k + 1) * s[k] > cum) tau = (cum - 1.0) / double(k + 1);
    }
    std::vector<double> w(z.size());
    for (std::size_t i = 0; i < z.size(); ++i) w[i] = std::max(0.0, z[i] - tau);
    return w;
}

// Keep the shortest prefix by decreasing weight reaching m, plus the ties of its last weight.
void ref_trim(std::vector<double>& w, double m) {
    if (!(m > 0 && m < 1)) return;
    std::vector<std::pair<double, std::size_t>> s;
    for (std::size_t i = 0; i < w.size(); ++i) s.push_back({w[i], i});
    std::sort(s.begin(), s.end(), [](auto a, auto b) { return a.first > b.first || (a.first == b.first && a.second < b.second); });
    double cum = 0, cut = s[0].first;
    for (auto& [x, i] : s) {
        if (x > 0) cut = x;
        cum += x;
        if (cum >= m) {
            cut = x;
            break;
        }
    }
    double kept = 0;
    for (auto& x : w) kept += x >= cut ? x : 0;
    for (auto& x : w) x = x >= cut ? x / kept : 0;
}

Reference reference(const Inputs& in, double voxel, const FusionParams& p) {
    std::map<Key, std::vector<int>> groups;
    for (std::size_t i = 0; i < in.n; ++i) {
        Key k;
        for (int a = 0; a < 3; ++a) k[a] = std::int32_t(std::round(double(in.positions[3 * i + a]) / voxel));
        groups[k].push_back(int(i));
    }
    Reference r;
    const int C = in.channels;
    for (const auto& [key, ids] : groups) {
        const std::size_t n = ids.size();
        r.keys.push_back(key);
        r.members.push_back(ids);
        r.occupancy.push_back(int(n));
        double mu[3] = {0, 0, 0};
        for (int i : ids)
            for (int a = 0; a < 3; ++a) mu[a] += in.positions[3 * i + a] / double(n);
        double var = 0;
        for (int i : ids)
            for (int a = 0; a < 3; ++a) var += std::pow(in.positions[3 * i + a] - mu[a], 2) / double(n);
        const double g = 1.0 / (1.0 + var / (voxel * voxel + p.eps));
        double mean_q = 0.5;
        std::vector<double> l(n, 0.0), raw(n, 0.0);
        if (!in.confidence.empty()) {
            mean_q = 0;
            for (std::size_t k = 0; k < n; ++k) {
                const double c = in.confidence[std::size_t(ids[k])];
                mean_q += ref_probability(c, p.confidence_mapping) / double(n);
                l[k] = ref_logit(c, p.confidence_mapping);
                raw[k] = c;
            }
        }
        const double rel = std::clamp((p.b_conf * mean_q + p.b_geo * g) / (p.b_conf + p.b_geo + p.eps), 0.0, 1.0);
        std::vector<double> w;
        double tau;
        if (p.policy == FusionPolicy::Mean) {
            w.assign(n, 1.0 / double(n));
            tau = INFINITY;
        } else if (p.policy == FusionPolicy::Softmax) {
            w = ref_softmax(raw);
            tau = 1;
        } else {
            tau = p.tau0 * std::pow(std::max(double(n) / p.n_ref, p.eps), -p.alpha) / (1 + p.k_rel * (1 - rel));
            tau = std::clamp(tau, p.tau_min, p.tau_max);
            std::vector<double> z(n);
            for (std::size_t k = 0; k < n; ++k) z[k] = l[k] / tau;
            w = p.weights == WeightFunction::Sparsemax ? ref_sparsemax(z) : ref_softmax(z);
            ref_trim(w, p.trim_mass);
        }
        double ws = 0, h = 0;
        int kept = 0, kept_min = 0;
        for (double x : w) {
            ws += x;
            kept += x > 0;
            kept_min += x > 1e-36;
            if (x > 0) h -= x * std::log(x);
        }
        for (int a = 0; a < 3; ++a) {
            double s = 0;
            for (std::size_t k = 0; k < n; ++k) s += w[k] * in.positions[3 * std::size_t(ids[k]) + a];
            r.positions.push_back(s / ws);
        }
        for (int c = 0; c < C; ++c) {
            double s = 0;
            for (std::size_t k = 0; k < n; ++k) s += w[k] * in.features[std::size_t(ids[k]) * C + c];
            r.features.push_back(s / ws);
        }
        r.temperature.push_back(tau);
        r.variance.push_back(var);
        r.reliability.push_back(rel);
        r.entropy.push_back(h);
        r.kept.push_back(kept);
        r.kept_min.push_back(kept_min);
        r.weights.push_back(w);
    }
    return r;
}

// ---------------------------------------------------------------------------------------------
// Helpers

Inputs random_inputs(std::size_t n, int channels, float extent, unsigned seed,
                     ConfidenceMapping conf = ConfidenceMapping::Logit, bool with_conf = true) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-extent, extent), f(-3.f, 3.f), prob(0.f, 1.f);
    std::normal_distribution<float> g(0.f, 2.f);
    Inputs in;
    in.n = n;
    in.channels = channels;
    in.positions.resize(3 * n);
    in.features.resize(n * std::size_t(channels));
    for (auto& x : in.positions) x = u(rng);
    for (auto& x : in.features) x = f(rng);
    if (with_conf) {
        in.confidence.resize(n);
        for (auto& c : in.confidence) {
            if (conf == ConfidenceMapping::Probability) c = prob(rng);
            else if (conf == ConfidenceMapping::Positive) c = 1.f + std::exp(g(rng));
            else c = g(rng);
        }
    }
    return in;
}

FeatureFusionResult fuse(const Inputs& in, double voxel, const FusionParams& p) {
    return fuse_voxels(in.positions.data(), in.n, in.features.data(), in.channels, voxel, in.conf(), p);
}

// |a - ref| <= tol * scale, with scale the largest magnitude among the voxel's inputs of that
// channel (the natural scale of a weighted mean), or 1e-30 when all are 0.
void compare(const FeatureFusionResult& got, const Reference& ref, const Inputs& in, double tol) {
    REQUIRE(got.size() == ref.keys.size());
    const int C = in.channels;
    for (std::size_t v = 0; v < ref.keys.size(); ++v) {
        INFO("voxel " << v << " occupancy " << ref.occupancy[v]);
        for (int a = 0; a < 3; ++a) REQUIRE(got.voxel_coords[3 * v + a] == ref.keys[v][a]);
        REQUIRE(got.diagnostics.occupancy[v] == ref.occupancy[v]);
        REQUIRE(got.diagnostics.kept[v] >= ref.kept_min[v]);
        REQUIRE(got.diagnostics.kept[v] <= ref.kept[v]);
        for (int a = 0; a < 3; ++a) {
            double scale = 1e-30;
            for (int i : ref.members[v]) scale = std::max(scale, std::abs(double(in.positions[3 * std::size_t(i) + a])));
            REQUIRE(std::abs(got.positions[3 * v + a] - ref.positions[3 * v + a]) <= tol * scale);
        }
        for (int c = 0; c < C; ++c) {
            double scale = 1e-30;
            for (int i : ref.members[v]) scale = std::max(scale, std::abs(double(in.features[std::size_t(i) * C + c])));
            INFO("channel " << c);
            REQUIRE(std::abs(got.features[v * C + c] - ref.features[v * C + c]) <= tol * scale);
        }
        const double t = ref.temperature[v];
        if (std::isinf(t)) REQUIRE(std::isinf(got.diagnostics.temperature[v]));
        else REQUIRE(got.diagnostics.temperature[v] == Approx(t).epsilon(1e-5));
        REQUIRE(got.diagnostics.variance[v] == Approx(ref.variance[v]).epsilon(1e-4).margin(1e-12));
        REQUIRE(got.diagnostics.reliability[v] == Approx(ref.reliability[v]).epsilon(1e-5));
        REQUIRE(got.diagnostics.entropy[v] == Approx(ref.entropy[v]).margin(1e-5));
    }
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

void require_identical(const FeatureFusionResult& a, const FeatureFusionResult& b) {
    REQUIRE(a.voxel_coords == b.voxel_coords);
    REQUIRE(same_bits(a.positions, b.positions));
    REQUIRE(same_bits(a.features, b.features));
    REQUIRE(a.diagnostics.occupancy == b.diagnostics.occupancy);
    REQUIRE(a.diagnostics.kept == b.diagnostics.kept);
    REQUIRE(same_bits(a.diagnostics.temperature, b.diagnostics.temperature));
    REQUIRE(same_bits(a.diagnostics.variance, b.diagnostics.variance));
    REQUIRE(same_bits(a.diagnostics.reliability, b.diagnostics.reliability));
    REQUIRE(same_bits(a.diagnostics.entropy, b.diagnostics.entropy));
}

// The samples perm[0], perm[1], ... of `in` (a permutation, or a subset).
Inputs permuted(const Inputs& in, const std::vector<std::size_t>& perm) {
    Inputs out;
    out.n = perm.size();
    out.channels = in.channels;
    const std::size_t C = std::size_t(in.channels);
    out.positions.resize(3 * out.n);
    out.features.resize(C * out.n);
    if (!in.confidence.empty()) out.confidence.resize(out.n);
    for (std::size_t j = 0; j < out.n; ++j) {
        const std::size_t i = perm[j];
        std::copy_n(&in.positions[3 * i], 3, &out.positions[3 * j]);
        std::copy_n(in.features.data() + C * i, C, out.features.data() + C * j);
        if (!in.confidence.empty()) out.confidence[j] = in.confidence[i];
    }
    return out;
}

std::vector<FusionParams> all_params() {
    std::vector<FusionParams> out;
    for (auto policy : {FusionPolicy::Mean, FusionPolicy::Softmax, FusionPolicy::Occupancy}) {
        FusionParams p;
        p.policy = policy;
        if (policy != FusionPolicy::Occupancy) {
            out.push_back(p);
            continue;
        }
        for (auto wf : {WeightFunction::Softmax, WeightFunction::Sparsemax})
            for (double trim : {0.0, 0.8}) {
                p.weights = wf;
                p.trim_mass = trim;
                out.push_back(p);
            }
    }
    return out;
}

}  // namespace

// -------------------------------------------------------------------------------------------------
// Against the reference

TEST_CASE("fuse_voxels matches the float64 brute-force reference", "[fusion]") {
    for (auto mapping : {ConfidenceMapping::Logit, ConfidenceMapping::Probability, ConfidenceMapping::Positive}) {
        const Inputs in = random_inputs(3000, 7, 1.f, 1 + unsigned(mapping), mapping);
        for (FusionParams p : all_params()) {
            p.confidence_mapping = mapping;
            for (auto precision : {Precision::Float32, Precision::Float64}) {
                p.precision = precision;
                INFO("policy " << int(p.policy) << " weights " << int(p.weights) << " trim " << p.trim_mass
                               << " mapping " << int(mapping) << " precision " << int(precision));
                const auto got = fuse(in, 0.1, p);  // about 5 samples per voxel, up to ~20
                compare(got, reference(in, 0.1, p), in, 1e-5);
            }
        }
    }
}

TEST_CASE("fuse_voxels float32 path stays within 1e-5 of the float64 path", "[fusion]") {
    const Inputs in = random_inputs(20000, 5, 1.f, 99);
    for (FusionParams p : all_params()) {
        p.precision = Precision::Float64;
        const auto ref = fuse(in, 0.07, p);
        p.precision = Precision::Float32;
        const auto got = fuse(in, 0.07, p);
        REQUIRE(got.voxel_coords == ref.voxel_coords);
        double worst = 0;
        for (std::size_t k = 0; k < got.features.size(); ++k)
            worst = std::max(worst, std::abs(double(got.features[k]) - ref.features[k]) / 3.0);  // |f| <= 3
        INFO("policy " << int(p.policy) << " worst relative error " << worst);
        CHECK(worst <= 1e-5);
        CHECK(got.diagnostics.kept == ref.diagnostics.kept);
    }
}

TEST_CASE("fuse_voxels without confidence and with no features", "[fusion]") {
    Inputs in = random_inputs(3000, 0, 1.f, 5, ConfidenceMapping::Logit, false);
    for (FusionParams p : all_params()) compare(fuse(in, 0.2, p), reference(in, 0.2, p), in, 1e-5);
    const auto empty = fuse_voxels(nullptr, 0, nullptr, 4, 0.1, nullptr, {});
    CHECK(empty.size() == 0);
    CHECK(empty.channels == 4);
}

// -------------------------------------------------------------------------------------------------
// Stiff and extreme inputs

TEST_CASE("a voxel with one sample is copied bit for bit", "[fusion]") {
    Inputs in = random_inputs(500, 9, 100.f, 3);
    for (std::size_t i = 0; i < in.n; ++i) in.positions[3 * i] = float(i) + 0.1f;  // one per voxel
    for (FusionParams p : all_params()) {
        const auto r = fuse(in, 1.0, p);
        REQUIRE(r.size() == in.n);
        for (std::size_t v = 0; v < in.n; ++v) {
            const std::size_t i = std::size_t(std::find(r.sample_voxel.begin(), r.sample_voxel.end(), int(v)) - r.sample_voxel.begin());
            REQUIRE(std::memcmp(&r.positions[3 * v], &in.positions[3 * i], 3 * sizeof(float)) == 0);
            REQUIRE(std::memcmp(&r.features[9 * v], &in.features[9 * i], 9 * sizeof(float)) == 0);
            REQUIRE(r.diagnostics.kept[v] == 1);
            REQUIRE(r.diagnostics.entropy[v] == 0.f);
            REQUIRE(r.diagnostics.variance[v] == 0.f);
        }
    }
}

TEST_CASE("confidences of +-1e30 and all-equal confidences give finite weights summing to 1", "[fusion]") {
    // One voxel of 6 samples; one-hot features, so the fused features are the weights.
    Inputs in;
    in.n = 6;
    in.channels = 6;
    in.positions = {0.1f, 0, 0, 0.2f, 0, 0, 0.3f, 0, 0, -0.1f, 0, 0, -0.2f, 0, 0, 0.05f, 0.1f, 0};
    in.features.assign(36, 0.f);
    for (int i = 0; i < 6; ++i) in.features[std::size_t(7 * i)] = 1.f;
    const std::vector<std::vector<float>> confs = {
        {1e30f, -1e30f, 1e30f, 0.f, -1e30f, 5.f}, {1e30f, 1e30f, 1e30f, 1e30f, 1e30f, 1e30f},
        {-1e30f, -1e30f, -1e30f, -1e30f, -1e30f, -1e30f}, {2.f, 2.f, 2.f, 2.f, 2.f, 2.f},
        {FLT_MAX, -FLT_MAX, 0.f, FLT_MAX, 1.f, -1.f}};
    for (const auto& c : confs) {
        in.confidence = c;
        for (FusionParams p : all_params()) {
            for (auto precision : {Precision::Float32, Precision::Float64}) {
                p.precision = precision;
                const auto r = fuse(in, 1.0, p);
                REQUIRE(r.size() == 1);
                double sum = 0;
                for (float w : r.features) {
                    REQUIRE(std::isfinite(w));
                    REQUIRE(w >= 0.f);
                    sum += w;
                }
                REQUIRE(sum == Approx(1.0).epsilon(1e-6));
                const bool all_equal = std::equal(c.begin() + 1, c.end(), c.begin());
                if (all_equal || p.policy == FusionPolicy::Mean)
                    for (float w : r.features) REQUIRE(w == Approx(1.0 / 6).epsilon(1e-6));
                if (c[0] == 1e30f && c[1] == -1e30f && p.policy != FusionPolicy::Mean) {
                    // The two samples at +1e30 share the weight.
                    REQUIRE(r.features[0] == Approx(0.5).epsilon(1e-6));
                    REQUIRE(r.features[2] == Approx(0.5).epsilon(1e-6));
                }
                const auto ref = reference(in, 1.0, p);
                compare(r, ref, in, 1e-5);
            }
        }
    }
}

TEST_CASE("one dominant sample among 1e5 takes all the weight", "[fusion]") {
    const std::size_t n = 100000;
    Inputs in = random_inputs(n, 3, 0.45f, 17);  // all in voxel (0,0,0) of size 1
    std::fill(in.confidence.begin(), in.confidence.end(), 0.f);
    in.confidence[4321] = 50.f;
    FusionParams p;
    for (auto precision : {Precision::Float32, Precision::Float64}) {
        p.precision = precision;
        const auto r = fuse(in, 1.0, p);
        REQUIRE(r.size() == 1);
        CHECK(r.diagnostics.kept[0] == 1);
        CHECK(r.diagnostics.entropy[0] == 0.f);
        CHECK(r.diagnostics.temperature[0] == float(p.tau_min));  // n / n_ref is large
        for (int c = 0; c < 3; ++c) CHECK(r.features[std::size_t(c)] == in.features[4321 * 3 + std::size_t(c)]);
        for (int a = 0; a < 3; ++a) CHECK(r.positions[std::size_t(a)] == in.positions[4321 * 3 + std::size_t(a)]);
    }
    p.policy = FusionPolicy::Softmax;  // exp(-50) * 1e5 ~ 2e-17: the dominant sample to float precision
    const auto r = fuse(in, 1.0, p);
    for (int c = 0; c < 3; ++c) CHECK(r.features[std::size_t(c)] == Approx(in.features[4321 * 3 + std::size_t(c)]).epsilon(1e-6));
}

TEST_CASE("temperature clips at tau_min and at tau_max", "[fusion]") {
    Inputs in = random_inputs(2000, 2, 0.45f, 23);  // one voxel, n / n_ref = 250
    FusionParams p;
    auto r = fuse(in, 1.0, p);
    REQUIRE(r.diagnostics.temperature[0] == float(p.tau_min));
    compare(r, reference(in, 1.0, p), in, 1e-5);
    // A voxel of 2 samples with a large tau0 clips at tau_max.
    Inputs two = random_inputs(2, 2, 0.45f, 29);
    p.tau0 = 50.0;
    r = fuse(two, 1.0, p);
    REQUIRE(r.diagnostics.temperature[0] == float(p.tau_max));
    compare(r, reference(two, 1.0, p), two, 1e-5);
}

TEST_CASE("a million samples in one voxel", "[fusion]") {
    const Inputs in = random_inputs(1000000, 2, 0.45f, 31);
    FusionParams p;
    const auto r = fuse(in, 1.0, p);
    REQUIRE(r.size() == 1);
    CHECK(r.diagnostics.occupancy[0] == 1000000);
    compare(r, reference(in, 1.0, p), in, 1e-5);
}

TEST_CASE("samples all at one point have variance 0 and full geometric consistency", "[fusion]") {
    Inputs in = random_inputs(50, 4, 0.3f, 37);
    for (std::size_t i = 0; i < in.n; ++i) {
        in.positions[3 * i] = 0.125f;
        in.positions[3 * i + 1] = -0.25f;
        in.positions[3 * i + 2] = 0.f;
    }
    FusionParams p;
    p.b_conf = 0.0;  // r = b_geo g / (b_geo + eps) with g = 1
    const auto r = fuse(in, 1.0, p);
    REQUIRE(r.size() == 1);
    CHECK(r.diagnostics.variance[0] == 0.f);
    CHECK(r.diagnostics.reliability[0] == Approx(1.0).epsilon(1e-6));
    CHECK(r.positions == std::vector<float>{0.125f, -0.25f, 0.f});
    compare(r, reference(in, 1.0, p), in, 1e-5);
}

TEST_CASE("coordinates whose key overflows int32 are a clear error", "[fusion]") {
    Inputs in = random_inputs(10, 2, 1.f, 41);
    in.positions[3 * 6 + 2] = 1e7f;
    CHECK_THROWS_WITH(fuse(in, 1e-3, {}), Contains("positions[6, 2]") && Contains("int32"));
    FusionParams drop;
    drop.on_invalid = InvalidPolicy::Drop;
    CHECK_THROWS_WITH(fuse(in, 1e-3, drop), Contains("positions[6, 2]"));
}

TEST_CASE("NaN and Inf inputs raise naming the field, or are dropped and counted", "[fusion]") {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const Inputs clean = random_inputs(400, 3, 1.f, 43);
    FusionParams raise, drop;
    drop.on_invalid = InvalidPolicy::Drop;
    struct Case {
        const char* message;
        std::function<void(Inputs&)> spoil;
        std::vector<std::size_t> bad;
    };
    const std::vector<Case> cases = {
        {"positions[7, 1]", [&](Inputs& in) { in.positions[3 * 7 + 1] = nan; in.positions[3 * 90] = -inf; }, {7, 90}},
        {"features[12, 2]", [&](Inputs& in) { in.features[12 * 3 + 2] = inf; in.features[300 * 3] = nan; }, {12, 300}},
        {"confidence[5]", [&](Inputs& in) { in.confidence[5] = nan; in.confidence[6] = -inf; }, {5, 6}},
    };
    for (const auto& c : cases) {
        INFO(c.message);
        Inputs in = clean;
        c.spoil(in);
        CHECK_THROWS_WITH(fuse(in, 0.3, raise), Contains(c.message) && Contains("NaN or Inf"));
        const auto r = fuse(in, 0.3, drop);
        CHECK(r.dropped == c.bad.size());
        // The same as fusing the clean samples alone.
        std::vector<std::size_t> rest;
        for (std::size_t i = 0; i < in.n; ++i)
            if (std::find(c.bad.begin(), c.bad.end(), i) == c.bad.end()) rest.push_back(i);
        const Inputs sub = permuted(in, rest);
        const auto expected = fuse(sub, 0.3, raise);
        require_identical(r, expected);
        for (std::size_t i : c.bad) CHECK(r.sample_voxel[i] == -1);
    }
    // A confidence outside its mapping's domain.
    Inputs in = random_inputs(50, 1, 1.f, 47, ConfidenceMapping::Probability);
    in.confidence[9] = 1.5f;
    FusionParams prob;
    prob.confidence_mapping = ConfidenceMapping::Probability;
    CHECK_THROWS_WITH(fuse(in, 0.3, prob), Contains("confidence[9] = 1.5") && Contains("outside [0, 1]"));
    in.confidence[9] = 1.f;  // the bounds are valid: logit +-FLT_MAX
    CHECK_NOTHROW(fuse(in, 0.3, prob));
    FusionParams pos;
    pos.confidence_mapping = ConfidenceMapping::Positive;
    in.confidence[9] = -0.5f;
    CHECK_THROWS_WITH(fuse(in, 0.3, pos), Contains("confidence[9]") && Contains("negative"));
}

// -------------------------------------------------------------------------------------------------
// Invariants

TEST_CASE("permuting the inputs changes no bit of the result", "[fusion]") {
    Inputs in = random_inputs(30000, 6, 1.f, 53);
    // Some samples share a position (tie broken by confidence) or position and confidence (by
    // features).
    for (std::size_t i = 0; i < 200; ++i) {
        std::copy_n(&in.positions[3 * i], 3, &in.positions[3 * (i + 1000)]);
        if (i % 2) in.confidence[i + 1000] = in.confidence[i];
    }
    std::vector<std::size_t> perm(in.n);
    std::iota(perm.begin(), perm.end(), 0);
    std::shuffle(perm.begin(), perm.end(), std::mt19937(59));
    const Inputs shuffled = permuted(in, perm);
    // Voxels of about 2, 60 and 900 samples: every path of the canonical order.
    for (double voxel : {0.08, 0.25, 0.6}) {
        INFO("voxel " << voxel);
        for (FusionParams p : all_params()) {
            const auto a = fuse(in, voxel, p), b = fuse(shuffled, voxel, p);
            require_identical(a, b);
            for (std::size_t j = 0; j < in.n; ++j) REQUIRE(b.sample_voxel[j] == a.sample_voxel[perm[j]]);
        }
    }
}

TEST_CASE("the result is the same for 1 and 2 threads", "[fusion]") {
    const Inputs in = random_inputs(40000, 4, 1.f, 61);
    const int threads = omp_get_max_threads();
    for (FusionParams p : all_params()) {
        omp_set_num_threads(1);
        const auto a = fuse(in, 0.05, p);
        omp_set_num_threads(2);
        const auto b = fuse(in, 0.05, p);
        omp_set_num_threads(threads);
        require_identical(a, b);
        REQUIRE(a.sample_voxel == b.sample_voxel);
    }
}

TEST_CASE("translating by whole voxels translates the result", "[fusion]") {
    // Positions on a 1/64 lattice and a voxel of 0.25, so that the shifted inputs are exact.
    Inputs in = random_inputs(5000, 3, 1.f, 67);
    for (auto& x : in.positions) x = std::round(x * 64.f) / 64.f + 1.f / 256.f;
    Inputs moved = in;
    const int shift[3] = {3, -7, 12};
    for (std::size_t i = 0; i < in.n; ++i)
        for (int a = 0; a < 3; ++a) moved.positions[3 * i + a] += 0.25f * float(shift[a]);
    for (FusionParams p : all_params()) {
        const auto a = fuse(in, 0.25, p), b = fuse(moved, 0.25, p);
        REQUIRE(a.size() == b.size());
        for (std::size_t v = 0; v < a.size(); ++v) {
            for (int k = 0; k < 3; ++k) {
                REQUIRE(b.voxel_coords[3 * v + k] == a.voxel_coords[3 * v + k] + shift[k]);
                REQUIRE(b.positions[3 * v + k] == Approx(a.positions[3 * v + k] + 0.25f * float(shift[k])).margin(1e-5));
            }
            REQUIRE(b.diagnostics.kept[v] == a.diagnostics.kept[v]);
        }
        for (std::size_t k = 0; k < a.features.size(); ++k) REQUIRE(b.features[k] == Approx(a.features[k]).margin(3e-5));
    }
}

TEST_CASE("occupancy with trim off, alpha 0, k_rel 0 and tau0 1 equals softmax", "[fusion]") {
    const Inputs in = random_inputs(20000, 5, 1.f, 71);
    FusionParams occ, soft;
    occ.trim_mass = 0.0;
    occ.alpha = 0.0;
    occ.k_rel = 0.0;
    occ.tau0 = 1.0;
    soft.policy = FusionPolicy::Softmax;
    const auto a = fuse(in, 0.06, occ), b = fuse(in, 0.06, soft);
    REQUIRE(same_bits(a.positions, b.positions));
    REQUIRE(same_bits(a.features, b.features));
    REQUIRE(same_bits(a.diagnostics.temperature, b.diagnostics.temperature));
    REQUIRE(a.diagnostics.kept == b.diagnostics.kept);
}

TEST_CASE("occupancy without confidence equals mean", "[fusion]") {
    const Inputs in = random_inputs(20000, 5, 1.f, 73, ConfidenceMapping::Logit, false);
    FusionParams occ, mean;
    mean.policy = FusionPolicy::Mean;
    for (auto wf : {WeightFunction::Softmax, WeightFunction::Sparsemax}) {
        occ.weights = wf;
        const auto a = fuse(in, 0.06, occ), b = fuse(in, 0.06, mean);
        REQUIRE(same_bits(a.positions, b.positions));
        REQUIRE(same_bits(a.features, b.features));
        REQUIRE(a.diagnostics.kept == a.diagnostics.occupancy);
        REQUIRE(same_bits(a.diagnostics.entropy, b.diagnostics.entropy));
    }
}

// -------------------------------------------------------------------------------------------------
// Header primitives (fusion_weights.h), on hand-computed cases

TEST_CASE("fusion_weights primitives on hand-computed cases", "[fusion][fusion_weights]") {
    namespace fw = fusion_weights;
    // sparsemax of z = (1, 0.5, -1): support {1, 0.5}, threshold 0.25 -> (0.75, 0.25, 0).
    const double l[3] = {1.0, 0.5, -1.0};
    double w[3], scratch[4];
    fw::sparsemax_weights<double>(l, 3, 1.0, w, scratch);
    CHECK(w[0] == Approx(0.75));
    CHECK(w[1] == Approx(0.25));
    CHECK(w[2] == 0.0);
    // At temperature 0.25 the gap of 0.5 becomes 2 > 1: only the leader.
    fw::sparsemax_weights<double>(l, 3, 0.25, w, scratch);
    CHECK(w[0] == 1.0);
    CHECK(w[1] == 0.0);

    // softmax at +-1e30 in float: finite, the two leaders share.
    const float big[4] = {1e30f, -1e30f, 1e30f, 3.f};
    float wf[4];
    fw::softmax_weights<float>(big, 4, 0.15f, wf);
    CHECK(wf[0] == 0.5f);
    CHECK(wf[1] == 0.f);
    CHECK(wf[2] == 0.5f);
    CHECK(wf[3] == 0.f);

    // Trimming (0.4, 0.3, 0.2, 0.1) to 0.65 keeps 0.4 and 0.3, renormalised.
    double t[4] = {0.1, 0.4, 0.2, 0.3};
    CHECK(fw::trim_weights<double>(t, 4, 0.65, scratch) == 2);
    CHECK(t[0] == 0.0);
    CHECK(t[1] == Approx(4.0 / 7));
    CHECK(t[2] == 0.0);
    CHECK(t[3] == Approx(3.0 / 7));
    // Ties at the cut are kept together: (0.4, 0.2, 0.2, 0.2) to 0.5 keeps all four.
    double u[4] = {0.2, 0.4, 0.2, 0.2};
    CHECK(fw::trim_weights<double>(u, 4, 0.5, scratch) == 4);
    CHECK(u[1] == Approx(0.4));
    // Off: 0 and 1.
    CHECK(fw::trim_weights<double>(t, 4, 0.0, scratch) == 2);
    CHECK(fw::trim_weights<double>(t, 4, 1.0, scratch) == 2);

    // Entropy: uniform over 4 -> log 4; one-hot -> 0.
    const double uni[4] = {0.25, 0.25, 0.25, 0.25}, hot[3] = {0, 1, 0};
    CHECK(fw::weight_entropy<double>(uni, 4) == Approx(std::log(4.0)));
    CHECK(fw::weight_entropy<double>(hot, 3) == 0.0);

    // Temperature: 0.7 * (16 / 8)^-0.5 / (1 + 1 * (1 - 0.5)) = 0.32998...
    CHECK(fw::temperature<double>(16, 0.5, 0.7, 0.5, 8, 0.15, 2.0, 1.0, 1e-6) == Approx(0.7 / std::sqrt(2.0) / 1.5));
    CHECK(fw::temperature<double>(100000, 0.5, 0.7, 0.5, 8, 0.15, 2.0, 1.0, 1e-6) == 0.15);
    CHECK(fw::temperature<double>(1, 1.0, 5.0, 0.5, 8, 0.15, 2.0, 1.0, 1e-6) == 2.0);
    // Reliability and geometric consistency.
    CHECK(fw::geometric_consistency<double>(0.01, 0.1, 0.0) == Approx(0.5));
    CHECK(fw::reliability<double>(0.5, 0.5, 1.0, 2.0, 0.0) == Approx(0.5));
    CHECK(fw::reliability<double>(1.0, 1.0, 1.0, 2.0, 0.0) == 1.0);

    // Confidence mappings.
    CHECK(fw::confidence_logit<double>(0.75f, ConfidenceMapping::Probability) == Approx(std::log(3.0)));
    CHECK(fw::confidence_logit<double>(1.f, ConfidenceMapping::Probability) == double(FLT_MAX));
    CHECK(fw::confidence_logit<double>(0.f, ConfidenceMapping::Positive) == -double(FLT_MAX));
    CHECK(fw::confidence_probability<double>(3.f, ConfidenceMapping::Positive) == 0.75);
    CHECK(fw::confidence_probability<float>(-200.f, ConfidenceMapping::Logit) >= 0.f);
    CHECK(fw::confidence_probability<double>(0.f, ConfidenceMapping::Logit) == 0.5);
    CHECK_FALSE(fw::confidence_valid(-0.1f, ConfidenceMapping::Positive));
    CHECK_FALSE(fw::confidence_valid(1.01f, ConfidenceMapping::Probability));
    CHECK(fw::confidence_valid(-1e30f, ConfidenceMapping::Logit));
}

TEST_CASE("fusion_weights sort_descending matches std::sort for every size path", "[fusion][fusion_weights]") {
    std::mt19937 rng(83);
    std::uniform_int_distribution<int> small(0, 5);  // few distinct values: many ties
    std::normal_distribution<float> g;
    for (long long n : {1LL, 2LL, 3LL, 7LL, 15LL, 16LL, 17LL, 31LL, 32LL, 33LL, 100LL, 1000LL}) {
        for (int trial = 0; trial < 20; ++trial) {
            std::vector<float> a(static_cast<std::size_t>(n));
            for (auto& x : a) {
                const int kind = small(rng);
                x = kind == 0 ? -INFINITY : kind == 1 ? 0.f : kind == 2 ? 1e30f : kind == 3 ? -1e30f : g(rng);
            }
            std::vector<float> expected = a;
            std::sort(expected.begin(), expected.end(), std::greater<float>());
            std::vector<double> d(a.begin(), a.end());
            std::vector<float> h = a;
            fusion_weights::sort_descending<float>(a.data(), n);
            fusion_weights::sort_descending<double>(d.data(), n);
            fusion_weights::heap_sort_descending<float>(h.data(), n);  // the device path
            INFO("n " << n);
            REQUIRE(a == expected);
            REQUIRE(std::equal(d.begin(), d.end(), expected.begin()));
            REQUIRE(h == expected);
        }
    }
}

TEST_CASE("fusion parameters are validated", "[fusion]") {
    const Inputs in = random_inputs(10, 1, 1.f, 79);
    const auto bad = [&](auto set, const char* field) {
        FusionParams p;
        set(p);
        CHECK_THROWS_WITH(fuse(in, 0.5, p), Contains(std::string("FusionParams.") + field));
    };
    bad([](FusionParams& p) { p.tau0 = 0; }, "tau0");
    bad([](FusionParams& p) { p.alpha = -1; }, "alpha");
    bad([](FusionParams& p) { p.n_ref = 0; }, "n_ref");
    bad([](FusionParams& p) { p.tau_min = 0; }, "tau_min");
    bad([](FusionParams& p) { p.tau_max = 0.1; }, "tau_max");
    bad([](FusionParams& p) { p.k_rel = NAN; }, "k_rel");
    bad([](FusionParams& p) { p.trim_mass = 1.5; }, "trim_mass");
    bad([](FusionParams& p) { p.eps = -1; }, "eps");
    CHECK_THROWS_WITH(fuse(in, -0.5, {}), Contains("voxel_size"));
}

// -------------------------------------------------------------------------------------------------
// Gaussians

namespace {

GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed, float extent) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-extent, extent), s(0.01f, 0.2f), o(0.f, 1.f), q(-1.f, 1.f);
    std::normal_distribution<float> g(0.f, 2.f);
    GaussianCloud c(n, degree);
    for (auto& x : c.means) x = u(rng);
    for (auto& x : c.scales) x = s(rng);
    for (auto& x : c.rotations) x = q(rng);
    for (auto& x : c.opacities) x = o(rng);
    for (auto& x : c.sh) x = q(rng);
    c.confidence.resize(n);
    for (auto& x : c.confidence) x = g(rng);
    std::vector<float> e(n);
    for (auto& x : e) x = u(rng);
    c.set_extra("depth", e);
    return c;
}

Inputs as_inputs(const GaussianCloud& c) {
    Inputs in;
    in.n = c.size();
    in.positions = c.means;
    in.confidence = c.confidence;
    in.channels = 1;
    in.features = c.opacities;
    return in;
}

}  // namespace

TEST_CASE("fuse_gaussians fuses means, SH, opacity, confidence and extras like the reference", "[fusion][gaussians]") {
    const GaussianCloud c = random_cloud(4000, 2, 83, 1.f);
    for (FusionParams p : all_params()) {
        const auto r = fuse_gaussians(c, 0.15, p);
        const Reference ref = reference(as_inputs(c), 0.15, p);
        REQUIRE(r.size() == ref.keys.size());
        const std::size_t k3 = 27;
        for (std::size_t v = 0; v < r.size(); ++v) {
            const auto& w = ref.weights[v];
            const auto& ids = ref.members[v];
            double op = 0, conf = 0, depth = 0, ws = 0;
            std::vector<double> sh(k3, 0.0);
            for (std::size_t k = 0; k < ids.size(); ++k) {
                const std::size_t i = std::size_t(ids[k]);
                ws += w[k];
                op += w[k] * c.opacities[i];
                conf += w[k] * c.confidence[i];
                depth += w[k] * c.extras[0].values[i];
                for (std::size_t j = 0; j < k3; ++j) sh[j] += w[k] * c.sh[k3 * i + j];
            }
            for (int a = 0; a < 3; ++a) REQUIRE(r.cloud.means[3 * v + a] == Approx(ref.positions[3 * v + a]).margin(1e-5));
            REQUIRE(r.cloud.opacities[v] == Approx(op / ws).margin(1e-5));
            REQUIRE(r.cloud.confidence[v] == Approx(conf / ws).margin(2e-5));
            REQUIRE(r.cloud.extras[0].values[v] == Approx(depth / ws).margin(1e-5));
            for (std::size_t j = 0; j < k3; ++j) REQUIRE(r.cloud.sh[k3 * v + j] == Approx(sh[j] / ws).margin(1e-5));
            REQUIRE(r.diagnostics.kept[v] == ref.kept[v]);
            if (ids.size() > 1) {
                const Eigen::Vector4f q(&r.cloud.rotations[4 * v]);
                REQUIRE(q.norm() == Approx(1.0f).epsilon(1e-6));
                REQUIRE(q[0] >= 0.f);
            }
        }
        validate(r.cloud);
    }
}

TEST_CASE("fuse_gaussians shape: average of log-scales and aligned quaternions", "[fusion][gaussians]") {
    GaussianCloud c(2, 0);
    c.means = {0.1f, 0.f, 0.f, -0.1f, 0.f, 0.f};
    c.scales = {0.1f, 0.2f, 0.4f, 0.4f, 0.2f, 0.1f};
    const Eigen::Quaternionf q(Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 2, 3).normalized()));
    // The same rotation as q and -q (scaled): aligned to one hemisphere they average to q.
    c.rotations = {q.w(), q.x(), q.y(), q.z(), -2 * q.w(), -2 * q.x(), -2 * q.y(), -2 * q.z()};
    const auto r = fuse_gaussians(c, 1.0, {});
    REQUIRE(r.size() == 1);
    for (int a = 0; a < 3; ++a) CHECK(r.cloud.scales[std::size_t(a)] == Approx(std::sqrt(c.scales[std::size_t(a)] * c.scales[std::size_t(3 + a)])));
    CHECK(r.cloud.rotations[0] == Approx(q.w()));
    CHECK(r.cloud.rotations[1] == Approx(q.x()));
    CHECK(r.cloud.rotations[2] == Approx(q.y()));
    CHECK(r.cloud.rotations[3] == Approx(q.z()));
    // A zero scale gives a zero geometric mean, never NaN.
    c.scales[0] = 0.f;
    CHECK(fuse_gaussians(c, 1.0, {}).cloud.scales[0] == 0.f);
}

TEST_CASE("fuse_gaussians shape: moment matching", "[fusion][gaussians]") {
    const GaussianCloud c = random_cloud(3000, 0, 89, 1.f);
    FusionParams p;
    p.shape = ShapeMode::Moment;
    const auto r = fuse_gaussians(c, 0.3, p);
    const Reference ref = reference(as_inputs(c), 0.3, p);
    REQUIRE(r.size() == ref.keys.size());
    for (std::size_t v = 0; v < r.size(); ++v) {
        const auto& ids = ref.members[v];
        if (ids.size() < 2) continue;
        const auto& w = ref.weights[v];
        // Reference: sum_i w_i (R_i S_i^2 R_i^T + d_i d_i^T), from scratch.
        Eigen::Vector3d mu(ref.positions[3 * v], ref.positions[3 * v + 1], ref.positions[3 * v + 2]);
        Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();
        double ws = 0;
        for (std::size_t k = 0; k < ids.size(); ++k) {
            const std::size_t i = std::size_t(ids[k]);
            Eigen::Quaterniond qi(c.rotations[4 * i], c.rotations[4 * i + 1], c.rotations[4 * i + 2], c.rotations[4 * i + 3]);
            const Eigen::Matrix3d R = qi.normalized().toRotationMatrix();
            const Eigen::Vector3d s(c.scales[3 * i], c.scales[3 * i + 1], c.scales[3 * i + 2]);
            const Eigen::Vector3d d = Eigen::Vector3d(c.means[3 * i], c.means[3 * i + 1], c.means[3 * i + 2]) - mu;
            sigma += w[k] * (R * s.cwiseAbs2().asDiagonal() * R.transpose() + d * d.transpose());
            ws += w[k];
        }
        sigma /= ws;
        const Eigen::Matrix3d got = r.cloud.covariance(v);
        INFO("voxel " << v);
        REQUIRE((got - sigma).norm() <= 1e-5 * sigma.norm());
        const Eigen::Vector4f q(&r.cloud.rotations[4 * v]);
        REQUIRE(q[0] >= 0.f);
    }
}

TEST_CASE("fuse_gaussians passes single Gaussians through and drops invalid ones", "[fusion][gaussians]") {
    GaussianCloud c = random_cloud(300, 1, 97, 1000.f);  // one per voxel at voxel 1
    for (FusionParams p : all_params()) {
        for (auto shape : {ShapeMode::Average, ShapeMode::Moment}) {
            p.shape = shape;
            const auto r = fuse_gaussians(c, 1.0, p);
            REQUIRE(r.size() == c.size());
            for (std::size_t i = 0; i < c.size(); ++i) {
                const std::size_t v = std::size_t(r.sample_voxel[i]);
                REQUIRE(std::memcmp(&r.cloud.rotations[4 * v], &c.rotations[4 * i], 16) == 0);  // not normalised
                REQUIRE(std::memcmp(&r.cloud.scales[3 * v], &c.scales[3 * i], 12) == 0);
                REQUIRE(std::memcmp(&r.cloud.means[3 * v], &c.means[3 * i], 12) == 0);
                REQUIRE(std::memcmp(&r.cloud.sh[12 * v], &c.sh[12 * i], 48) == 0);
                REQUIRE(r.cloud.opacities[v] == c.opacities[i]);
                REQUIRE(r.cloud.confidence[v] == c.confidence[i]);
                REQUIRE(r.cloud.extras[0].values[v] == c.extras[0].values[i]);
            }
        }
    }
    c.scales[3 * 17 + 1] = -0.1f;
    c.rotations[4 * 40] = c.rotations[4 * 40 + 1] = c.rotations[4 * 40 + 2] = c.rotations[4 * 40 + 3] = 0.f;
    c.sh[12 * 41] = std::numeric_limits<float>::quiet_NaN();
    CHECK_THROWS_WITH(fuse_gaussians(c, 1.0, {}), Contains("GaussianCloud.scales[17]"));
    FusionParams drop;
    drop.on_invalid = InvalidPolicy::Drop;
    const auto r = fuse_gaussians(c, 1.0, drop);
    CHECK(r.dropped == 3);
    CHECK(r.size() == c.size() - 3);
    CHECK(r.sample_voxel[17] == -1);
    CHECK(r.sample_voxel[40] == -1);
    CHECK(r.sample_voxel[41] == -1);
}

TEST_CASE("fuse_gaussians is invariant to permutation", "[fusion][gaussians]") {
    const GaussianCloud c = random_cloud(5000, 1, 101, 1.f);
    std::vector<std::size_t> perm(c.size());
    std::iota(perm.begin(), perm.end(), 0);
    std::shuffle(perm.begin(), perm.end(), std::mt19937(103));
    const GaussianCloud s = select(c, perm);
    for (auto shape : {ShapeMode::Average, ShapeMode::Moment}) {
        FusionParams p;
        p.shape = shape;
        const auto a = fuse_gaussians(c, 0.2, p), b = fuse_gaussians(s, 0.2, p);
        REQUIRE(same_bits(a.cloud.means, b.cloud.means));
        REQUIRE(same_bits(a.cloud.scales, b.cloud.scales));
        REQUIRE(same_bits(a.cloud.rotations, b.cloud.rotations));
        REQUIRE(same_bits(a.cloud.sh, b.cloud.sh));
        REQUIRE(same_bits(a.cloud.opacities, b.cloud.opacities));
        REQUIRE(same_bits(a.cloud.extras[0].values, b.cloud.extras[0].values));
    }
}

// -------------------------------------------------------------------------------------------------
// The fast paths of the weight maths against their plain definitions

namespace {

// Distance in units in the last place between two finite floats of the same sign.
long long ulp_distance(float a, float b) {
    std::int32_t ia, ib;
    std::memcpy(&ia, &a, sizeof ia);
    std::memcpy(&ib, &b, sizeof ib);
    return std::abs(static_cast<long long>(ia) - static_cast<long long>(ib));
}

}  // namespace

TEST_CASE("exp_nonpositive is within 2 ulp of exp in double, at any place in the array", "[fusion][fusion_weights]") {
    namespace fw = fusion_weights;
    std::vector<float> x;
    for (float v = 0.f; v > -110.f; v -= 0.0137f) x.push_back(v);
    // Reduction boundaries (k ln2 +- half an ulp), the subnormal range and the ends.
    for (int k = 0; k <= 150; ++k) {
        const float c = float(-k * 0.693147180559945309);
        x.insert(x.end(), {c, std::nextafter(c, 0.f), std::nextafter(c, -INFINITY)});
    }
    x.insert(x.end(), {-0.f, -1e-30f, -87.33654f, -87.34f, -103.2789f, -103.97f, -104.f, -1e30f, -FLT_MAX, -INFINITY});
    std::vector<float> got(x.size());
    fw::exp_nonpositive<float>(x.data(), (long long)x.size(), got.data());
    for (std::size_t i = 0; i < x.size(); ++i) {
        const float want = float(std::exp(double(x[i])));  // correctly rounded to within 1/2 ulp
        INFO("x = " << x[i] << ": got " << got[i] << ", want " << want);
        REQUIRE(std::isfinite(got[i]));
        REQUIRE(got[i] >= 0.f);
        if (want >= FLT_MIN) REQUIRE(ulp_distance(got[i], want) <= 2);
        else REQUIRE(std::abs(double(got[i]) - double(want)) <= 2.0 * double(std::numeric_limits<float>::denorm_min()));
    }
    CHECK(got[0] == 1.f);  // exp(0) = 1 exactly: a voxel's leader gets e = 1
    CHECK(got.back() == 0.f);
    // The same value gives the same bits in the SIMD body and in the tail, in place or not.
    for (std::size_t len = 1; len <= 9; ++len) {
        for (std::size_t at = 0; at < len; ++at) {
            std::vector<float> a(len, -1.f);
            a[at] = -3.3f;
            fw::exp_nonpositive<float>(a.data(), (long long)len, a.data());
            float single = -3.3f;
            fw::exp_nonpositive<float>(&single, 1, &single);
            REQUIRE(a[at] == single);
        }
    }
    // Doubles go through std::exp.
    const double xd[3] = {0.0, -1.5, -800.0};
    double gd[3];
    fw::exp_nonpositive<double>(xd, 3, gd);
    CHECK(gd[0] == 1.0);
    CHECK(gd[1] == std::exp(-1.5));
    CHECK(gd[2] == std::exp(-800.0));
}

TEST_CASE("sigmoid matches the Logit mapping's probability in double", "[fusion][fusion_weights]") {
    namespace fw = fusion_weights;
    std::vector<float> x = {0.f, -0.f, 1e-30f, -1e-30f, 0.5f, -0.5f, 10.f, -10.f, 88.f, -88.f, 104.f, -104.f,
                            200.f, -200.f, 1e30f, -1e30f, FLT_MAX, -FLT_MAX};
    for (float v = -30.f; v < 30.f; v += 0.071f) x.push_back(v);
    std::vector<float> q(x.size());
    fw::sigmoid<float>(x.data(), (long long)x.size(), q.data());
    for (std::size_t i = 0; i < x.size(); ++i) {
        const double want = fw::confidence_probability<double>(x[i], ConfidenceMapping::Logit);
        INFO("x = " << x[i] << ": got " << q[i] << ", want " << want);
        REQUIRE(q[i] >= 0.f);
        REQUIRE(q[i] <= 1.f);
        REQUIRE(std::abs(double(q[i]) - want) <= 4e-7 * want + 1e-44);
    }
    CHECK(q[0] == 0.5f);
}

namespace {

// n logits of which about 1 in `kinds` is `tie`, +1e30 or -1e30 each, the rest spread * N(0, 1):
// ties and extremes for the weight primitives.
std::vector<float> stiff_logits(std::mt19937& rng, long long n, int kinds, float tie, float spread) {
    std::normal_distribution<float> g;
    std::uniform_int_distribution<int> kind(0, kinds - 1);
    std::vector<float> l(static_cast<std::size_t>(n));
    for (auto& v : l) {
        const int k = kind(rng);
        v = k == 0 ? tie : k == 1 ? 1e30f : k == 2 ? -1e30f : spread * g(rng);
    }
    return l;
}

}  // namespace

TEST_CASE("softmax_trimmed matches softmax_weights, trim_weights and per-sample entropy", "[fusion][fusion_weights]") {
    namespace fw = fusion_weights;
    std::mt19937 rng(7);
    std::normal_distribution<float> g;
    for (long long n : {1LL, 2LL, 5LL, 9LL, 16LL, 17LL, 40LL, 300LL}) {
        for (int trial = 0; trial < 200; ++trial) {
            const std::vector<float> l = stiff_logits(rng, n, 10, 2.f, 3.f);
            const float tau = 0.15f + 2.f * std::abs(g(rng));
            const double m = trial % 3 == 0 ? 0.0 : 0.8;
            // softmax_trimmed against softmax_weights + trim_weights + weight_entropy, in double:
            // the same weights, kept count and entropy (random inputs never sit on a trimming cut).
            for (int precision = 0; precision < 2; ++precision) {
                std::vector<double> ld(l.begin(), l.end()), wd(l.size()), zd(l.size()), sd(l.size() + 1);
                std::vector<double> ref(l.size()), scratch(l.size() + 1);
                fw::softmax_weights<double>(ld.data(), n, double(tau), ref.data());
                const long long kept_ref = fw::trim_weights<double>(ref.data(), n, m, scratch.data());
                const double h_ref = fw::weight_entropy<double>(ref.data(), n);
                long long kept;
                double h;
                std::vector<double> got(l.size());
                if (precision == 0) {
                    std::vector<float> wf(l.size()), zf(l.size()), sf(l.size() + 1);
                    float hf;
                    kept = fw::softmax_trimmed<float>(l.data(), n, tau, m, wf.data(), zf.data(), sf.data(), &hf);
                    got.assign(wf.begin(), wf.end());
                    h = hf;
                } else {
                    kept = fw::softmax_trimmed<double>(ld.data(), n, double(tau), m, wd.data(), zd.data(), sd.data(), &h);
                    got = wd;
                }
                INFO("n " << n << " trial " << trial << (precision ? " double" : " float"));
                REQUIRE(kept == kept_ref);
                double sum = 0.0;
                for (long long i = 0; i < n; ++i) {
                    REQUIRE(got[i] == Approx(ref[i]).margin(2e-6));
                    REQUIRE((got[i] > 0.0) == (ref[i] > 0.0));
                    sum += got[i];
                }
                REQUIRE(sum == Approx(1.0).epsilon(1e-6));
                REQUIRE(h == Approx(h_ref).margin(2e-6));
            }
        }
    }
    // One sample, and one dominant sample: entropy exactly 0.
    float one = 3.f, w1, z1, s1, h1;
    CHECK(fw::softmax_trimmed<float>(&one, 1, 0.5f, 0.8, &w1, &z1, &s1, &h1) == 1);
    CHECK(w1 == 1.f);
    CHECK(h1 == 0.f);
    const float dom[4] = {50.f, 0.f, 0.f, 0.f};
    float w4[4], z4[4], s4[4], h4;
    CHECK(fw::softmax_trimmed<float>(dom, 4, 0.15f, 0.8, w4, z4, s4, &h4) == 1);
    CHECK(w4[0] == 1.f);
    CHECK(h4 == 0.f);
}

TEST_CASE("softmax_normalise_sorted trims like the sorting softmax_normalise", "[fusion][fusion_weights]") {
    namespace fw = fusion_weights;
    std::mt19937 rng(31);
    std::normal_distribution<float> g;
    for (long long n : {1LL, 2LL, 3LL, 9LL, 16LL, 17LL, 64LL, 500LL}) {
        for (int trial = 0; trial < 300; ++trial) {
            // Logits in decreasing order, with ties and extremes, as canonical order leaves them.
            std::vector<float> l = stiff_logits(rng, n, 8, 1.f, 2.f);
            std::sort(l.begin(), l.end(), std::greater<float>());
            const float tau = 0.15f + std::abs(g(rng));
            const double m = trial % 4 == 0 ? 0.0 : trial % 4 == 1 ? 0.5 : 0.8;
            std::vector<float> z(l.size()), e(l.size()), scratch(l.size());
            fw::softmax_logits<float>(l.data(), n, tau, z.data());
            fw::exp_nonpositive<float>(z.data(), n, e.data());
            std::vector<float> w1(e), w2(e);
            float h1, h2;
            const long long k1 = fw::softmax_normalise<float>(w1.data(), z.data(), n, m, scratch.data(), &h1);
            const long long k2 = fw::softmax_normalise_sorted<float>(w2.data(), z.data(), n, m, &h2);
            INFO("n " << n << " trial " << trial);
            REQUIRE(k1 == k2);
            for (long long i = 0; i < n; ++i) REQUIRE(w2[i] == Approx(w1[i]).margin(1e-7));
            REQUIRE(h2 == Approx(h1).margin(1e-6));
        }
    }
    // An exponential one ulp out of order is kept with its neighbour: everything >= the cut.
    float e[4] = {1.f, 0.5f, std::nextafter(0.5f, 1.f), 0.1f}, z[4] = {0.f, -0.69f, -0.69f, -2.3f}, h;
    CHECK(fw::softmax_normalise_sorted<float>(e, z, 4, 0.6, &h) == 3);
    CHECK(e[2] > e[1]);
    CHECK(e[3] == 0.f);
}
