// GaussianPlyWriter (a PLY written in parts) against write_ply of the whole cloud, byte for byte,
// and FusionStream's block sink against finish_gaussians().
#include "avsplat/core/error.h"
#include "avsplat/fusion/fusion_stream.h"
#include "avsplat/io/ply.h"

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

using namespace avsplat;

namespace {

std::string tmp_path(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

GaussianCloud cloud_of(std::size_t n, int degree, bool confidence, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> normal(0.f, 1.f);
    std::uniform_real_distribution<float> unit(0.01f, 0.99f);
    GaussianCloud c(n, degree);
    for (auto& v : c.means) v = normal(rng);
    for (auto& v : c.scales) v = 0.05f * unit(rng);
    for (auto& v : c.rotations) v = normal(rng);
    for (auto& v : c.opacities) v = unit(rng);
    for (auto& v : c.sh) v = normal(rng);
    if (confidence) {
        c.confidence.resize(n);
        for (auto& v : c.confidence) v = normal(rng);
    }
    std::vector<float> extra(n);
    for (auto& v : extra) v = normal(rng);
    c.set_extra("label", std::move(extra));
    return c;
}

GaussianCloud rows(const GaussianCloud& c, std::size_t b, std::size_t e) {
    std::vector<std::size_t> idx;
    for (std::size_t i = b; i < e; ++i) idx.push_back(i);
    return select(c, idx);
}

}  // namespace

TEST_CASE("GaussianPlyWriter writes write_ply's bytes for the parts concatenated", "[ply][stream]") {
    for (int degree : {0, 3}) {
        for (bool conf : {false, true}) {
            const GaussianCloud c = cloud_of(1000, degree, conf, 7 + unsigned(degree));
            const std::string whole = tmp_path("writer_whole.ply"), parts = tmp_path("writer_parts.ply");
            write_ply(whole, c);
            GaussianPlyWriter out(parts);
            out.append(rows(c, 0, 0));
            out.append(rows(c, 0, 333));
            out.append(rows(c, 333, 334));
            out.append(rows(c, 334, 1000));
            CHECK(out.size() == 1000);
            out.commit();
            CHECK(slurp(parts) == slurp(whole));
        }
    }
}

TEST_CASE("GaussianPlyWriter leaves the destination alone without commit, and checks parts", "[ply][stream]") {
    const std::string path = tmp_path("writer_keep.ply");
    {
        std::ofstream(path) << "old contents";
    }
    const GaussianCloud c = cloud_of(50, 1, false, 3);
    {
        GaussianPlyWriter out(path);
        out.append(c);
        CHECK_THROWS_WITH(out.append(cloud_of(5, 2, false, 4)), Catch::Contains("differ from the first part"));
        GaussianCloud bad = cloud_of(5, 1, false, 5);
        bad.scales[4] = -1.f;
        CHECK_THROWS_AS(out.append(bad), std::invalid_argument);
    }  // destroyed without commit
    CHECK(slurp(path) == "old contents");
    for (const auto& e : std::filesystem::directory_iterator(AVSPLAT_TEST_TMP))
        CHECK(e.path().filename().string().rfind(".avsplat-rows-", 0) != 0);
    CHECK_THROWS_AS(GaussianPlyWriter(tmp_path("no-such-folder/x.ply")), IOError);
    GaussianPlyWriter empty(tmp_path("writer_empty.ply"));
    empty.commit();
    CHECK(read_ply(tmp_path("writer_empty.ply")).size() == 0);
}

TEST_CASE("FusionStream's block sink gives finish_gaussians() block by block", "[fusion_stream][stream]") {
    const GaussianCloud c = cloud_of(6000, 1, true, 11);
    FusionParams p;
    const auto run = [&](auto&& finish) {
        FusionStream s(0.05, p, 64 << 10);
        for (std::size_t b = 0; b < c.size(); b += 700) s.add_gaussians(rows(c, b, std::min(c.size(), b + 700)));
        return finish(s);
    };
    const GaussianFusionResult ref = run([](FusionStream& s) { return s.finish_gaussians(); });
    std::size_t blocks = 0, calls = 0;
    std::vector<std::int32_t> coords;
    const std::string whole = tmp_path("sink_whole.ply"), parts = tmp_path("sink_parts.ply");
    write_ply(whole, ref.cloud);
    GaussianPlyWriter out(parts);
    std::size_t last_done = 0;
    const GaussianFusionResult summary = run([&](FusionStream& s) {
        s.set_progress([&](std::size_t done, std::size_t total) {
            CHECK(total == c.size());
            CHECK(done >= last_done);
            last_done = done;
            ++calls;
        });
        return s.finish_gaussians([&](GaussianFusionResult&& block) {
            CHECK(block.sample_voxel.empty());
            coords.insert(coords.end(), block.voxel_coords.begin(), block.voxel_coords.end());
            out.append(block.cloud);
            ++blocks;
        });
    });
    out.commit();
    CHECK(blocks > 1);
    CHECK(calls == blocks + 1);
    CHECK(last_done == c.size());
    CHECK(coords == ref.voxel_coords);
    CHECK(summary.sample_voxel == ref.sample_voxel);
    CHECK(summary.cloud.size() == 0);
    CHECK(slurp(parts) == slurp(whole));
}
