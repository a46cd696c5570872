// SOG (PlayCanvas): the codebooks and the palette k-means against brute force, the texel layout
// against hand-computed values, round trips within the format's quantisation, determinism, and
// hostile files.
#include "avsplat/core/error.h"
#include "avsplat/io/sog.h"
#include "io/sog/codebook.h"
#include "io/sog/sog_meta.h"
#include "io/sog/webp_image.h"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sys/stat.h>

using avsplat::GaussianCloud;
using avsplat::IOError;
using avsplat::SogFiles;
namespace sog = avsplat::sog;

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

GaussianCloud random_cloud(std::size_t n, int degree, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.f, 1.f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = 5.f * u(rng);
    for (auto& v : c.scales) v = std::exp(-4.f + 2.f * u(rng));
    for (auto& v : c.rotations) v = u(rng);
    for (auto& v : c.opacities) v = 0.5f + 0.5f * u(rng);
    for (auto& v : c.sh) v = 0.5f * u(rng);
    return c;
}

double log_transform(double v) { return std::copysign(std::log1p(std::fabs(v)), v); }

// Index of the original Gaussian at each decoded position (SOG stores Morton order): the nearest
// mean, brute force.
std::vector<std::size_t> match(const GaussianCloud& original, const GaussianCloud& decoded) {
    std::vector<std::size_t> m(decoded.size());
    for (std::size_t i = 0; i < decoded.size(); ++i) {
        double best = 1e300;
        for (std::size_t j = 0; j < original.size(); ++j) {
            double d = 0;
            for (int a = 0; a < 3; ++a) d += std::pow(double(decoded.means[3 * i + a]) - original.means[3 * j + a], 2);
            if (d < best) best = d, m[i] = j;
        }
    }
    return m;
}

std::size_t nearest_level(const std::vector<float>& levels, double v) {
    std::size_t best = 0;
    for (std::size_t k = 1; k < levels.size(); ++k)
        if (std::fabs(levels[k] - v) < std::fabs(levels[best] - v)) best = k;
    return best;
}

}  // namespace

TEST_CASE("SOG 1D codebook: exact for at most 256 levels, else a Lloyd fixed point", "[sog]") {
    std::vector<float> few;
    for (int i = 0; i < 1000; ++i) few.push_back(float(i % 200) * 0.37f - 3.f);
    const sog::Codebook1D exact = sog::fit_codebook(few);
    REQUIRE(exact.levels.size() == 256);
    for (float v : few) CHECK(exact.levels[exact.label(v)] == v);

    std::mt19937 rng(3);
    std::normal_distribution<float> g(0.f, 1.f);
    std::vector<float> many(20000);
    for (auto& v : many) v = g(rng) * (g(rng) > 1.5f ? 10.f : 1.f);
    const sog::Codebook1D cb = sog::fit_codebook(many);
    for (std::size_t k = 1; k < 256; ++k) CHECK(cb.levels[k - 1] <= cb.levels[k]);
    // Every value goes to its nearest level (brute force) ...
    std::vector<double> sum(256, 0.0);
    std::vector<int> count(256, 0);
    for (float v : many) {
        const std::size_t l = cb.label(v);
        CHECK(std::fabs(cb.levels[l] - v) <= std::fabs(cb.levels[nearest_level(cb.levels, v)] - v));
        sum[l] += v;
        ++count[l];
    }
    // ... and every used level is the mean of its values (Lloyd converged).
    for (std::size_t k = 0; k < 256; ++k)
        if (count[k]) CHECK(cb.levels[k] == Approx(sum[k] / count[k]).epsilon(1e-5).margin(1e-6));

    // log(0) = -inf gets a level 20 below the smallest finite value, as splat-transform's.
    const sog::Codebook1D inf = sog::fit_codebook({-INFINITY, 1.f, 2.f});
    CHECK(inf.levels[0] == -19.f);
    CHECK(inf.label(-INFINITY) == 0);
    CHECK(inf.levels[inf.label(2.f)] == 2.f);
}

TEST_CASE("SOG palette k-means: nearest-centre labels, identical for any thread count and seed-driven", "[sog]") {
    const std::size_t n = 3000;
    const int dims = 9;
    std::mt19937 rng(5);
    std::normal_distribution<float> g(0.f, 1.f);
    std::vector<float> pts(n * dims);
    for (auto& v : pts) v = g(rng);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const sog::Palette one = sog::fit_palette(pts.data(), n, dims, 256, 5, 7);
    omp_set_num_threads(4);
    const sog::Palette four = sog::fit_palette(pts.data(), n, dims, 256, 5, 7);
    omp_set_num_threads(threads);
    CHECK(one.centres == four.centres);
    CHECK(one.labels == four.labels);
    const sog::Palette other = sog::fit_palette(pts.data(), n, dims, 256, 5, 8);
    CHECK(other.centres != one.centres);
    REQUIRE(one.size == 256);
    for (std::size_t i = 0; i < n; i += 7) {
        auto dist = [&](std::size_t c) {
            double d = 0;
            for (int k = 0; k < dims; ++k) d += std::pow(double(pts[i * dims + k]) - one.centres[c * dims + k], 2);
            return d;
        };
        double best = 1e300;
        for (std::size_t c = 0; c < one.size; ++c) best = std::min(best, dist(c));
        CHECK(dist(one.labels[i]) <= best * (1 + 1e-5) + 1e-9);
    }
    // Lloyd lowers the error: more iterations never do worse than none.
    auto sse = [&](const sog::Palette& p) {
        double s = 0;
        for (std::size_t i = 0; i < n; ++i)
            for (int k = 0; k < dims; ++k) s += std::pow(double(pts[i * dims + k]) - p.centres[p.labels[i] * dims + k], 2);
        return s;
    };
    CHECK(sse(one) < sse(sog::fit_palette(pts.data(), n, dims, 256, 0, 7)));
    // No more vectors than entries: each is its own.
    const sog::Palette small = sog::fit_palette(pts.data(), 10, dims, 256, 5, 7);
    CHECK(small.size == 10);
    CHECK(small.labels[9] == 9);
}

TEST_CASE("SOG texels follow splat-transform's layout (hand-computed)", "[sog]") {
    GaussianCloud c(2, 0);
    c.means = {0.f, 0.f, 0.f, float(std::exp(1.0) - 1), -1.f, 0.f};
    c.rotations = {0, 0, 0, -2, 1, 0, 0, 0};  // z largest and negative: flipped, tag 255
    c.scales = {0.5f, 0.5f, 0.f, 1, 1, 1};
    c.opacities = {1.f, 0.2f};
    const SogFiles f = avsplat::encode_sog(c);
    const auto meta = nlohmann::json::parse(f.at("meta.json"));
    CHECK(meta["version"] == 2);
    CHECK(meta["count"] == 2);
    CHECK(meta["means"]["mins"][0].get<double>() == 0.0);
    CHECK(meta["means"]["maxs"][0].get<double>() == Approx(1.0));
    CHECK(meta["means"]["mins"][1].get<double>() == Approx(-std::log(2.0)));
    CHECK(!meta.contains("shN"));
    const sog::RgbaImage lo = sog::decode_webp(f.at("means_l.webp"), "l", 1 << 20);
    const sog::RgbaImage hi = sog::decode_webp(f.at("means_u.webp"), "u", 1 << 20);
    CHECK(lo.width == 4);
    CHECK(lo.height == 4);
    // Which Gaussian Morton order puts first: the texel whose x is 0 holds Gaussian 0.
    const sog::RgbaImage q = sog::decode_webp(f.at("quats.webp"), "q", 1 << 20);
    std::size_t first = lo.rgba[0] == 0 && hi.rgba[0] == 0 ? 0 : 1;
    const std::size_t t0 = first == 0 ? 0 : 1, t1 = 1 - t0;  // texels of Gaussians 0 and 1
    CHECK(int(hi.rgba[4 * t1]) == 255);
    CHECK(int(lo.rgba[4 * t1]) == 255);       // x = e - 1: log 1 = max: 65535
    CHECK(int(hi.rgba[4 * t0 + 1]) == 255);   // y = 0 is the max of y
    CHECK(int(hi.rgba[4 * t1 + 1]) == 0);     // y = -1 the min
    CHECK(int(q.rgba[4 * t0 + 3]) == 255);
    for (int k = 0; k < 3; ++k) CHECK(int(q.rgba[4 * t0 + k]) == 128);  // 255 * 0.5 = 127.5 -> 128
    CHECK(int(q.rgba[4 * t1 + 3]) == 252);
    const sog::RgbaImage s0 = sog::decode_webp(f.at("sh0.webp"), "s", 1 << 20);
    CHECK(int(s0.rgba[4 * t0 + 3]) == 255);
    CHECK(int(s0.rgba[4 * t1 + 3]) == 51);  // 0.2 * 255
    const GaussianCloud back = avsplat::decode_sog(f, "mem");
    CHECK(back.scales[3 * t0 + 2] < 1e-8f);  // scale 0 stays (near) 0
    CHECK(back.scales[3 * t0] == Approx(0.5f));
    CHECK(back.rotations[4 * t0 + 3] == Approx(1.0));
    CHECK(back.means[3 * t1] == Approx(std::exp(1.0) - 1).epsilon(1e-6));
    CHECK(back.means[3 * t1 + 1] == Approx(-1.0).epsilon(1e-6));
}

TEST_CASE("SOG round trip stays within the format's quantisation for SH degree 0..3", "[sog]") {
    for (int degree = 0; degree <= 3; ++degree) {
        const GaussianCloud c = random_cloud(700, degree, 11 + degree);
        const SogFiles f = avsplat::encode_sog(c);
        const auto meta = nlohmann::json::parse(f.at("meta.json"));
        const GaussianCloud d = avsplat::decode_sog(f, "mem");
        REQUIRE(d.size() == c.size());
        REQUIRE(d.sh_degree == degree);
        const auto m = match(c, d);
        const std::vector<float> scales_cb = meta["scales"]["codebook"].get<std::vector<float>>();
        const std::vector<float> sh0_cb = meta["sh0"]["codebook"].get<std::vector<float>>();
        const int K = c.sh_coeffs();
        std::vector<int> seen(c.size(), 0);
        for (std::size_t i = 0; i < d.size(); ++i) {
            const std::size_t j = m[i];
            ++seen[j];
            for (int a = 0; a < 3; ++a) {
                const double range = meta["means"]["maxs"][a].get<double>() - meta["means"]["mins"][a].get<double>();
                CHECK(std::fabs(log_transform(d.means[3 * i + a]) - log_transform(c.means[3 * j + a])) <=
                      0.5 * range / 65535 + 1e-6);
                // Scale: the codebook level nearest to the log scale.
                CHECK(std::log(d.scales[3 * i + a]) ==
                      Approx(scales_cb[nearest_level(scales_cb, std::log(c.scales[3 * j + a]))]).epsilon(1e-6));
                CHECK(d.sh[i * K * 3 + a] == sh0_cb[nearest_level(sh0_cb, c.sh[j * K * 3 + a])]);
            }
            CHECK(std::fabs(d.opacities[i] - c.opacities[j]) <= 0.5 / 255 + 1e-7);
            const Eigen::Vector4d qa = c.rotation(j).cast<double>().normalized();
            const Eigen::Vector4d qb = d.rotation(i).cast<double>();
            CHECK(qb.norm() == Approx(1.0).epsilon(1e-6));
            // Each of the three smaller components to within half an 8-bit step of [-1, 1] / sqrt(2).
            CHECK(std::fabs(qa.dot(qb)) >= 1 - 4 * std::pow(1.0 / 255 / std::sqrt(2.0), 2) * 3);
        }
        for (int s : seen) CHECK(s == 1);
        if (degree > 0) {
            // 700 vectors into a palette of 512: the SH-rest error is bounded by the spread.
            double err = 0, norm = 0;
            for (std::size_t i = 0; i < d.size(); ++i)
                for (int k = 3; k < K * 3; ++k) {
                    err += std::pow(double(d.sh[i * K * 3 + k]) - c.sh[m[i] * K * 3 + k], 2);
                    norm += std::pow(double(c.sh[m[i] * K * 3 + k]), 2);
                }
            CHECK(err < 0.5 * norm);
            CHECK(meta["shN"]["count"] == 512);
            CHECK(meta["shN"]["bands"] == degree);
        }
    }
}

TEST_CASE("SOG writing is deterministic across runs and thread counts, and folder and zip read alike", "[sog]") {
    const GaussianCloud c = random_cloud(1500, 3, 2);
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const SogFiles a = avsplat::encode_sog(c);
    omp_set_num_threads(3);
    const SogFiles b = avsplat::encode_sog(c);
    omp_set_num_threads(threads);
    CHECK(a == b);
    avsplat::SogWriteOptions other;
    other.seed = 1;
    CHECK(avsplat::encode_sog(c, other).at("shN_labels.webp") != a.at("shN_labels.webp"));

    avsplat::write_sog(tmp("det.sog"), c);
    avsplat::write_sog(tmp("det_folder"), c);
    avsplat::write_sog(tmp("det_meta_dir/"), c);
    const GaussianCloud mem = avsplat::decode_sog(a, "mem");
    for (const std::string& p : {tmp("det.sog"), tmp("det_folder"), tmp("det_folder/meta.json")}) {
        const GaussianCloud r = avsplat::read_sog(p);
        CHECK(r.means == mem.means);
        CHECK(r.sh == mem.sh);
        CHECK(r.rotations == mem.rotations);
    }
    // The zip form holds meta.json first, as splat-transform writes it.
    std::ifstream in(tmp("det.sog"), std::ios::binary);
    std::string zip((std::istreambuf_iterator<char>(in)), {});
    CHECK(zip.compare(30, 9, "meta.json") == 0);
    CHECK(avsplat::parse_sog(zip.data(), zip.size(), "mem.sog").means == mem.means);
}

TEST_CASE("SOG with zero Gaussians writes and reads", "[sog]") {
    const GaussianCloud empty(0, 2);
    const GaussianCloud back = avsplat::decode_sog(avsplat::encode_sog(empty), "mem");
    CHECK(back.size() == 0);
    CHECK(back.sh_degree == 2);
}

TEST_CASE("Hostile SOG files raise IOError naming the file and the field", "[sog]") {
    const SogFiles good = avsplat::encode_sog(random_cloud(300, 1, 4));
    auto fails = [&](SogFiles f, const std::string& needle) {
        CHECK_THROWS_AS(avsplat::decode_sog(f, "bad"), IOError);
        CHECK_THROWS_WITH(avsplat::decode_sog(f, "bad"), Catch::Contains(needle));
    };
    auto with_meta = [&](auto edit) {
        auto j = nlohmann::json::parse(good.at("meta.json"));
        edit(j);
        SogFiles f = good;
        f["meta.json"] = j.dump();
        return f;
    };
    SogFiles f = good;
    f.erase("quats.webp");
    fails(f, "bad/quats.webp: missing");
    f = good;
    f.erase("meta.json");
    fails(f, "no meta.json");
    f = good;
    f["sh0.webp"] = "RIFF\x10\0\0\0WEBPVP8L garbage";
    fails(f, "bad/sh0.webp");
    f = good;
    f["scales.webp"].resize(f["scales.webp"].size() / 2);
    fails(f, "bad/scales.webp");
    fails(with_meta([](auto& j) { j["count"] = 100000; }), "fewer than the 100000 Gaussians");
    fails(with_meta([](auto& j) { j["count"] = 1e12; }), "\"count\" must be a whole number in 0..67108864");
    fails(with_meta([](auto& j) { j["count"] = -1; }), "\"count\"");
    fails(with_meta([](auto& j) { j["count"] = 2.5; }), "\"count\"");
    fails(with_meta([](auto& j) { j.erase("version"); }), "\"means.shape\" is missing (no \"version\": read as a SOG version 1");
    fails(with_meta([](auto& j) { j["version"] = 3; }), "\"version\"");
    fails(with_meta([](auto& j) { j["scales"]["codebook"].erase(0); }), "\"scales.codebook\" must be an array of 256");
    fails(with_meta([](auto& j) { j["sh0"]["codebook"][7] = "x"; }), "\"sh0.codebook[7]\" must be a number");
    fails(with_meta([](auto& j) { j["scales"]["codebook"][3] = 1000; }), "\"scales.codebook[3]\"");
    fails(with_meta([](auto& j) { j["means"]["files"][0] = "../../etc/passwd"; }), "\"means.files[0]\" must be a plain file name");
    fails(with_meta([](auto& j) { j["means"]["mins"][2] = 1e6; }), "means");
    fails(with_meta([](auto& j) { j["means"].erase("maxs"); }), "\"means.maxs\" is missing");
    fails(with_meta([](auto& j) { j["shN"]["bands"] = 4; }), "\"shN.bands\"");
    fails(with_meta([](auto& j) { j["shN"]["bands"] = 2; }), "width 192 is not 512");
    fails(with_meta([](auto& j) { j["shN"]["count"] = 200; }), "outside the palette of 200 entries");
    fails(with_meta([](auto& j) { j["shN"]["count"] = 1; }), "bad/shN_centroids.webp: 192 x 4 texels, more than");
    fails(with_meta([](auto& j) { j["quats"]["files"][0] = "sh0.webp"; }), "not a largest-component tag");
    f = good;
    f["meta.json"] = "{\"version\": 2, \"count\": ";
    fails(f, "not valid JSON");
    f["meta.json"] = std::string(100, '[') + std::string(100, ']');
    fails(f, "nested deeper");

    // Files on disk: a folder without an image, a truncated .sog, a zip without meta.json.
    avsplat::write_sog(tmp("hostile_folder"), random_cloud(50, 0, 1));
    std::remove(tmp("hostile_folder/quats.webp").c_str());
    CHECK_THROWS_WITH(avsplat::read_sog(tmp("hostile_folder")), Catch::Contains("quats.webp: missing"));
    avsplat::write_sog(tmp("hostile.sog"), random_cloud(50, 0, 1));
    std::ifstream in(tmp("hostile.sog"), std::ios::binary);
    std::string zip((std::istreambuf_iterator<char>(in)), {});
    for (std::size_t cut : {std::size_t(10), zip.size() / 2, zip.size() - 5}) {
        std::ofstream(tmp("truncated.sog"), std::ios::binary).write(zip.data(), std::streamsize(cut));
        CHECK_THROWS_AS(avsplat::read_sog(tmp("truncated.sog")), IOError);
        CHECK_THROWS_AS(avsplat::parse_sog(zip.data(), cut, "cut.sog"), IOError);
    }
    CHECK_THROWS_WITH(avsplat::read_sog(tmp("no_such.sog")), Catch::Contains("no_such.sog"));
    ::mkdir(tmp("empty_dir").c_str(), 0777);
    CHECK_THROWS_WITH(avsplat::read_sog(tmp("empty_dir")), Catch::Contains("without meta.json"));
}

TEST_CASE("SOG writer refuses bad options and invalid clouds", "[sog]") {
    GaussianCloud c = random_cloud(10, 0, 1);
    avsplat::SogWriteOptions o;
    o.palette_size = 70000;
    CHECK_THROWS_AS(avsplat::encode_sog(c, o), std::invalid_argument);
    o = {};
    o.iterations = -1;
    CHECK_THROWS_AS(avsplat::encode_sog(c, o), std::invalid_argument);
    c.opacities[3] = 2.f;
    CHECK_THROWS_AS(avsplat::write_sog(tmp("invalid.sog"), c), std::invalid_argument);
    std::ifstream probe(tmp("invalid.sog"));
    CHECK(!probe.good());
}

TEST_CASE("SOG palette grouped search: near the exhaustive k-means' error and identical for any thread count", "[sog]") {
    // Auto's rule: grouped from 3e10 multiply-adds per pass and 1024 entries on.
    CHECK(sog::grouped_palette_search(32768, 32768, 45));
    CHECK_FALSE(sog::grouped_palette_search(16384, 16384, 45));
    CHECK_FALSE(sog::grouped_palette_search(100000000, 1000, 45));
    const std::size_t n = 20000, k = 2048;
    const int dims = 45;
    std::mt19937 rng(11);
    std::normal_distribution<float> g(0.f, 1.f);
    // Clustered vectors (400 clusters, spread 0.2) and plain noise (no structure: the hard case).
    std::vector<float> hubs(400 * dims), clustered(n * dims), noise(n * dims);
    for (auto& v : hubs) v = g(rng);
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t h = std::size_t(rng() % 400);
        for (int d = 0; d < dims; ++d) clustered[i * dims + d] = hubs[h * dims + d] + 0.2f * g(rng);
    }
    for (auto& v : noise) v = g(rng);
    for (const std::vector<float>* pts : {&clustered, &noise}) {
        INFO((pts == &clustered ? "clustered" : "noise"));
        auto sse = [&](const sog::Palette& p) {
            double s = 0;
            for (std::size_t i = 0; i < n; ++i)
                for (int d = 0; d < dims; ++d)
                    s += std::pow(double((*pts)[i * dims + d]) - p.centres[p.labels[i] * dims + d], 2);
            return s;
        };
        const sog::Palette exact = sog::fit_palette(pts->data(), n, dims, k, 5, 3, sog::PaletteSearch::Exhaustive);
        const int threads = omp_get_max_threads();
        omp_set_num_threads(1);
        const sog::Palette one = sog::fit_palette(pts->data(), n, dims, k, 5, 3, sog::PaletteSearch::Grouped);
        omp_set_num_threads(4);
        const sog::Palette four = sog::fit_palette(pts->data(), n, dims, k, 5, 3, sog::PaletteSearch::Grouped);
        omp_set_num_threads(threads);
        CHECK(one.centres == four.centres);
        CHECK(one.labels == four.labels);
        REQUIRE(one.size == k);
        const double ratio = sse(one) / sse(exact);
        INFO("grouped / exhaustive error " << ratio);
        CHECK(ratio < (pts == &clustered ? 1.001 : 1.02));
        // Most labels are the nearest entry of the grouped palette itself (brute force).
        std::size_t nearest = 0;
        for (std::size_t i = 0; i < n; ++i) {
            auto dist = [&](std::size_t c) {
                double s = 0;
                for (int d = 0; d < dims; ++d)
                    s += std::pow(double((*pts)[i * dims + d]) - one.centres[c * dims + d], 2);
                return s;
            };
            double best = 1e300;
            for (std::size_t c = 0; c < k; ++c) best = std::min(best, dist(c));
            nearest += dist(one.labels[i]) <= best * (1 + 1e-5) + 1e-9;
        }
        INFO("nearest " << nearest << " of " << n);
        CHECK(double(nearest) >= (pts == &clustered ? 0.999 : 0.9) * double(n));
    }
}

TEST_CASE("SOG palette: scale-free near float's limits, and equal vectors on one entry", "[sog]") {
    // Clustered vectors scaled by 2^100 and 2^-100: their squares overflow and underflow float,
    // where the search compares them; the palette must be the unscaled one, scaled (exactly).
    const std::size_t n = 6000, k = 1024;
    const int dims = 45;
    std::mt19937 rng(12);
    std::normal_distribution<float> g(0.f, 1.f);
    std::vector<float> hubs(200 * dims), pts(n * dims);
    for (auto& v : hubs) v = g(rng);
    for (std::size_t i = 0; i < n; ++i) {
        const std::size_t h = std::size_t(rng() % 200);
        for (int d = 0; d < dims; ++d) pts[i * dims + d] = hubs[h * dims + d] + 0.2f * g(rng);
    }
    for (const sog::PaletteSearch how : {sog::PaletteSearch::Exhaustive, sog::PaletteSearch::Grouped}) {
        const sog::Palette plain = sog::fit_palette(pts.data(), n, dims, k, 3, 5, how);
        for (const int e : {100, -100}) {
            INFO("scale 2^" << e << (how == sog::PaletteSearch::Grouped ? ", grouped" : ", exhaustive"));
            std::vector<float> scaled(pts.size());
            for (std::size_t i = 0; i < pts.size(); ++i) scaled[i] = std::ldexp(pts[i], e);
            const sog::Palette p = sog::fit_palette(scaled.data(), n, dims, k, 3, 5, how);
            CHECK(p.labels == plain.labels);
            std::size_t exact = 0;
            for (std::size_t c = 0; c < plain.centres.size(); ++c)
                exact += p.centres[c] == std::ldexp(plain.centres[c], e);
            CHECK(exact == plain.centres.size());
        }
    }
    // All vectors equal (higher SH bands all 0): every entry is that vector.
    const std::vector<float> zeros(n * dims, 0.f);
    for (const sog::PaletteSearch how : {sog::PaletteSearch::Exhaustive, sog::PaletteSearch::Grouped}) {
        const sog::Palette p = sog::fit_palette(zeros.data(), n, dims, k, 3, 5, how);
        CHECK(p.size == k);
        CHECK(std::all_of(p.centres.begin(), p.centres.end(), [](float v) { return v == 0.f; }));
        CHECK(std::all_of(p.labels.begin(), p.labels.end(), [&](std::uint32_t l) { return l < k; }));
    }
}
