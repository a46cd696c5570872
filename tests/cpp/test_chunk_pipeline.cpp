// io/chunk_pipeline.h: the sink sees every chunk once, in order, with the bytes the fill wrote;
// an exception on either side stops both and reaches the caller; and write_ply, which writes
// through it, reports a failing device after several chunks as an OutputError.
#include "avsplat/core/error.h"
#include "avsplat/io/ply.h"
#include "io/chunk_pipeline.h"

#include <catch2/catch.hpp>

#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

using avsplat::detail::pipeline_chunks;

TEST_CASE("pipeline_chunks hands every chunk to the sink in order", "[io]") {
    for (std::size_t chunks : {0u, 1u, 2u, 3u, 17u}) {
        std::vector<std::string> data;
        pipeline_chunks(
            chunks, 64,
            [](std::size_t k, char* buf) {
                const std::string s = "chunk " + std::to_string(k);
                std::memcpy(buf, s.data(), s.size());
                return s.size();
            },
            [&](const char* buf, std::size_t n) { data.emplace_back(buf, n); });
        REQUIRE(data.size() == chunks);
        for (std::size_t k = 0; k < chunks; ++k) CHECK(data[k] == "chunk " + std::to_string(k));
    }
}

TEST_CASE("pipeline_chunks stops both sides on an exception and rethrows it", "[io]") {
    SECTION("from the fill: no chunk after the failing one reaches the sink") {
        std::vector<std::size_t> sunk;
        CHECK_THROWS_WITH(pipeline_chunks(
                              10, 8,
                              [](std::size_t k, char* buf) -> std::size_t {
                                  if (k == 4) throw std::runtime_error("fill failed at 4");
                                  std::memcpy(buf, &k, sizeof k);
                                  return sizeof k;
                              },
                              [&](const char* buf, std::size_t) {
                                  std::size_t k;
                                  std::memcpy(&k, buf, sizeof k);
                                  sunk.push_back(k);
                              }),
                          "fill failed at 4");
        REQUIRE(sunk.size() <= 4);
        for (std::size_t i = 0; i < sunk.size(); ++i) CHECK(sunk[i] == i);
    }
    SECTION("from the sink: the fill stops within two chunks") {
        std::size_t filled = 0;
        CHECK_THROWS_WITH(pipeline_chunks(
                              1000, 8, [&](std::size_t, char*) { return ++filled, std::size_t(0); },
                              [n = 0](const char*, std::size_t) mutable {
                                  if (++n == 2) throw std::runtime_error("sink failed at 1");
                              }),
                          "sink failed at 1");
        CHECK(filled <= 4);
    }
}

TEST_CASE("write_ply to a full device fails cleanly after several chunks", "[io][ply]") {
    // 100,000 Gaussians of SH degree 3 are about 25 MB: several of the writer's 8 MB chunks.
    const std::size_t n = 100000;
    avsplat::GaussianCloud c;
    c.sh_degree = 3;
    c.means.assign(3 * n, 0.5f);
    c.scales.assign(3 * n, 0.01f);
    c.rotations.assign(4 * n, 0.0f);
    for (std::size_t i = 0; i < n; ++i) c.rotations[4 * i] = 1.0f;
    c.opacities.assign(n, 0.5f);
    c.sh.assign(n * 16 * 3, 0.1f);
    try {
        avsplat::write_ply("/dev/full", c);
        FAIL("/dev/full accepted the write");
    } catch (const avsplat::OutputError& e) {
        CHECK(std::string(e.what()).find("/dev/full: write failed: No space left on device") == 0);
    }
}
