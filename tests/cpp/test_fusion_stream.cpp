// FusionStream against the in-memory operators (bit for bit), and the spill file's round trip.
#include "avsplat/fusion/fusion_stream.h"
#include "fusion/spill_file.h"

#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

using namespace avsplat;

namespace {

// Bitwise equality (NaN-safe, -0 != +0), as np.array_equal on the bits.
template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

bool same_diagnostics(const VoxelDiagnostics& a, const VoxelDiagnostics& b) {
    return same_bits(a.occupancy, b.occupancy) && same_bits(a.temperature, b.temperature) &&
           same_bits(a.variance, b.variance) && same_bits(a.reliability, b.reliability) &&
           same_bits(a.kept, b.kept) && same_bits(a.entropy, b.entropy);
}

struct Scene {
    std::size_t n;
    int c;
    std::vector<float> p, f, conf;
};

// A dense ball in a sparse background, in random order.
Scene make_scene(std::size_t n, int c, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> dense(0.f, 0.2f), value(0.f, 1.f);
    std::uniform_real_distribution<float> sparse(-4.f, 4.f);
    Scene s{n, c, std::vector<float>(3 * n), std::vector<float>(n * std::size_t(c)), std::vector<float>(n)};
    for (std::size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) s.p[3 * i + a] = i % 4 ? dense(rng) : sparse(rng);
    for (auto& x : s.f) x = value(rng);
    for (auto& x : s.conf) x = 2.f * value(rng);
    return s;
}

}  // namespace

TEST_CASE("spill file: segments come back in order, bit for bit", "[fusion_stream]") {
    const std::string path = std::string(AVSPLAT_TEST_TMP) + "/spill_roundtrip.bin";
    detail::SpillFile file(path);
    detail::SampleTable a({3, 2}), b({3, 2});
    for (std::uint64_t i = 0; i < 5; ++i) {
        a.index.push_back(10 + i);
        for (int k = 0; k < 3; ++k) a.columns[0].push_back(float(i) + 0.1f * float(k));
        for (int k = 0; k < 2; ++k) a.columns[1].push_back(-float(i) - 0.5f * float(k));
    }
    const std::uint32_t rows[] = {4, 0, 2};
    b.append_rows(a, rows, 3);
    file.append(a);
    file.append(b);
    CHECK(file.samples() == 8);
    const detail::SampleTable all = file.read_all({3, 2});
    REQUIRE(all.size() == 8);
    CHECK(all.index == std::vector<std::uint64_t>{10, 11, 12, 13, 14, 14, 10, 12});
    CHECK(all.columns[0][3 * 5] == 4.f);
    CHECK(all.columns[1][2 * 6 + 1] == -0.5f);
    file.remove();
    CHECK_FALSE(std::filesystem::exists(path));
}

TEST_CASE("FusionStream equals fuse_voxels for every policy under a spilling limit", "[fusion_stream]") {
    const Scene s = make_scene(5000, 3, 7);
    for (FusionPolicy policy : {FusionPolicy::Mean, FusionPolicy::Softmax, FusionPolicy::Occupancy}) {
        FusionParams params;
        params.policy = policy;
        const FeatureFusionResult ref = fuse_voxels(s.p.data(), s.n, s.f.data(), s.c, 0.1, s.conf.data(), params);
        FusionStream stream(0.1, params, 32 << 10, AVSPLAT_TEST_TMP);
        std::mt19937 rng(3);
        for (std::size_t at = 0; at < s.n;) {
            const std::size_t m = std::min<std::size_t>(s.n - at, 1 + rng() % 700);
            stream.add(&s.p[3 * at], m, &s.f[at * std::size_t(s.c)], s.c, &s.conf[at]);
            at += m;
        }
        REQUIRE(stream.num_blocks() > 8);
        const std::string folder = stream.work_folder();
        CHECK(std::filesystem::is_directory(folder));
        const FeatureFusionResult got = stream.finish();
        CHECK_FALSE(std::filesystem::exists(folder));
        CHECK(same_bits(got.positions, ref.positions));
        CHECK(same_bits(got.features, ref.features));
        CHECK(same_bits(got.voxel_coords, ref.voxel_coords));
        CHECK(same_bits(got.sample_voxel, ref.sample_voxel));
        CHECK(same_diagnostics(got.diagnostics, ref.diagnostics));
        CHECK(got.dropped == ref.dropped);
    }
}

TEST_CASE("FusionStream equals fuse_gaussians for both shape modes", "[fusion_stream]") {
    const Scene s = make_scene(3000, 1, 11);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(0.01f, 0.1f), q(-1.f, 1.f), o(0.f, 1.f);
    GaussianCloud cloud(s.n, 1);
    cloud.means = s.p;
    for (auto& x : cloud.scales) x = u(rng);
    for (auto& x : cloud.rotations) x = q(rng);
    for (auto& x : cloud.opacities) x = o(rng);
    for (auto& x : cloud.sh) x = q(rng);
    cloud.confidence = s.conf;
    for (ShapeMode shape : {ShapeMode::Average, ShapeMode::Moment}) {
        FusionParams params;
        params.shape = shape;
        const GaussianFusionResult ref = fuse_gaussians(cloud, 0.1, params);
        FusionStream stream(0.1, params, 64 << 10);
        for (std::size_t at = 0; at < s.n; at += 500) {
            std::vector<std::size_t> idx;
            for (std::size_t i = at; i < std::min(s.n, at + 500); ++i) idx.push_back(i);
            GaussianCloud part(idx.size(), 1);
            for (std::size_t k = 0; k < idx.size(); ++k) {
                const std::size_t i = idx[k];
                std::memcpy(&part.means[3 * k], &cloud.means[3 * i], 3 * sizeof(float));
                std::memcpy(&part.scales[3 * k], &cloud.scales[3 * i], 3 * sizeof(float));
                std::memcpy(&part.rotations[4 * k], &cloud.rotations[4 * i], 4 * sizeof(float));
                std::memcpy(&part.sh[12 * k], &cloud.sh[12 * i], 12 * sizeof(float));
                part.opacities[k] = cloud.opacities[i];
            }
            part.confidence.assign(cloud.confidence.begin() + long(at), cloud.confidence.begin() + long(at + idx.size()));
            stream.add_gaussians(part);
        }
        REQUIRE(stream.num_blocks() > 1);
        const GaussianFusionResult got = stream.finish_gaussians();
        CHECK(same_bits(got.cloud.means, ref.cloud.means));
        CHECK(same_bits(got.cloud.scales, ref.cloud.scales));
        CHECK(same_bits(got.cloud.rotations, ref.cloud.rotations));
        CHECK(same_bits(got.cloud.opacities, ref.cloud.opacities));
        CHECK(same_bits(got.cloud.sh, ref.cloud.sh));
        CHECK(same_bits(got.cloud.confidence, ref.cloud.confidence));
        CHECK(same_bits(got.voxel_coords, ref.voxel_coords));
        CHECK(same_bits(got.sample_voxel, ref.sample_voxel));
        CHECK(same_diagnostics(got.diagnostics, ref.diagnostics));
    }
}
