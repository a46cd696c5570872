// FusionStream against the in-memory operators (bit for bit), and the spill file's round trip.
#include "avsplat/core/error.h"
#include "avsplat/fusion/fusion_stream.h"
#include "fusion/spill_file.h"

#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <random>
#include <string>
#include <thread>
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

namespace {

// Runs f in a forked child; returns its wait status (a crash is WIFSIGNALED).
template <class F>
int in_child(const F& f) {
    const pid_t pid = fork();
    if (pid == 0) {
        int code = 0;
        try {
            code = f();
        } catch (...) {
            code = 99;
        }
        _exit(code);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    return status;
}

}  // namespace

TEST_CASE("FusionStream is closed with a clear error after an add that failed to spill", "[fusion_stream]") {
    const Scene s = make_scene(4000, 2, 13);
    const std::string root = std::string(AVSPLAT_TEST_TMP) + "/stream_vanishing_work_dir";
    std::filesystem::remove_all(root);
    std::filesystem::create_directories(root);
    const int status = in_child([&] {
        FusionStream stream(0.1, {}, 32 << 10, root);
        std::filesystem::remove_all(root);  // the work folder vanishes before the first spill
        bool failed = false;
        try {
            stream.add(s.p.data(), s.n, s.f.data(), s.c);
        } catch (const IOError&) {
            failed = true;
        }
        if (!failed) return 1;
        std::string closed;
        try {
            stream.add(s.p.data(), 10, s.f.data(), s.c);
        } catch (const std::logic_error& e) {
            closed = e.what();
        }
        if (closed.find("closed because an earlier add failed") == std::string::npos) return 2;
        try {
            stream.finish();
        } catch (const std::logic_error&) {
            return 0;
        }
        return 3;
    });
    REQUIRE(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 0);
}

TEST_CASE("FusionStream refuses a call made while another call on it runs", "[fusion_stream]") {
    const Scene s = make_scene(2000, 2, 17);
    FusionStream stream(0.1, {}, 32 << 10, AVSPLAT_TEST_TMP);
    stream.add(s.p.data(), s.n, s.f.data(), s.c);
    std::string refused;
    stream.set_progress([&](std::size_t, std::size_t) {
        if (!refused.empty()) return;
        try {
            stream.add(s.p.data(), 10, s.f.data(), s.c);
            refused = "accepted";
        } catch (const std::logic_error& e) {
            refused = e.what();
        }
    });
    const FeatureFusionResult got = stream.finish();
    CHECK(refused.find("another call on it runs") != std::string::npos);
    CHECK(got.sample_voxel.size() == s.n);
}

TEST_CASE("FusionStream fed from four threads at once neither crashes nor miscounts", "[fusion_stream]") {
    const Scene s = make_scene(20000, 2, 19);
    const int status = in_child([&] {
        FusionStream stream(0.05, {}, 64 << 10, AVSPLAT_TEST_TMP);
        std::atomic<std::size_t> accepted{0}, refused{0};
        std::vector<std::thread> threads;
        for (int t = 0; t < 4; ++t)
            threads.emplace_back([&, t] {
                for (std::size_t at = std::size_t(t) * 500; at + 500 <= s.n; at += 2000) {
                    try {
                        stream.add(&s.p[3 * at], 500, &s.f[at * 2], s.c);
                        accepted += 500;
                    } catch (const std::logic_error&) {
                        refused += 500;
                    }
                }
            });
        for (auto& th : threads) th.join();
        if (accepted + refused != s.n) return 1;
        if (stream.num_samples() != accepted) return 2;
        const FeatureFusionResult got = stream.finish();
        return got.sample_voxel.size() == accepted ? 0 : 3;
    });
    REQUIRE(WIFEXITED(status));
    CHECK(WEXITSTATUS(status) == 0);
}

TEST_CASE("FusionStream removes the spill folders of killed processes when it spills", "[fusion_stream]") {
    const std::string root = std::string(AVSPLAT_TEST_TMP) + "/stream_stale_folders";
    std::filesystem::remove_all(root);
    std::filesystem::create_directories(root);
    const Scene s = make_scene(4000, 2, 23);
    // A process SIGKILLed while its stream had spilled.
    const pid_t killed = fork();
    if (killed == 0) {
        FusionStream stream(0.1, {}, 32 << 10, root);
        stream.add(s.p.data(), s.n, s.f.data(), s.c);
        ::kill(::getpid(), SIGKILL);
    }
    int status = 0;
    waitpid(killed, &status, 0);
    REQUIRE(WIFSIGNALED(status));
    std::vector<std::string> left;
    for (const auto& e : std::filesystem::directory_iterator(root)) left.push_back(e.path().filename().string());
    REQUIRE(left.size() == 1);
    CHECK(left[0].rfind("avsplat-fusion-" + std::to_string(killed) + "-", 0) == 0);
    FusionStream stream(0.1, {}, 32 << 10, root);
    stream.add(s.p.data(), s.n, s.f.data(), s.c);
    CHECK_FALSE(std::filesystem::exists(root + "/" + left[0]));
    CHECK(std::filesystem::is_directory(stream.work_folder()));  // its own stays
    stream.finish();
    CHECK(std::filesystem::is_empty(root));
}
