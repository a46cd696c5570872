// Registration (registration/): the robust Umeyama fit against known transforms and a
// hand-computed case, the pose graph against a loop with known drift, chunk alignment and
// stitching on simulated chunked captures against their true transforms.
#include "avsplat/registration/chunk_alignment.h"
#include "avsplat/registration/pose_graph.h"
#include "avsplat/registration/similarity.h"
#include "avsplat/registration/stitch.h"
#include "avsplat/sim/chunked_capture.h"

#include <catch2/catch.hpp>

#include <Eigen/Geometry>

#include <omp.h>

#include <cmath>
#include <random>
#include <vector>

using namespace avsplat;

namespace {

Similarity random_similarity(std::mt19937& rng) {
    std::normal_distribution<double> g;
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Similarity T;
    T.rotation = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized().toRotationMatrix();
    T.translation = Eigen::Vector3d(3 * u(rng), 3 * u(rng), 3 * u(rng));
    T.scale = std::exp(u(rng));
    return T;
}

double angle_deg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
    return Eigen::AngleAxisd(a.transpose() * b).angle() * 180.0 / 3.14159265358979323846;
}

}  // namespace

TEST_CASE("similarity_from_correspondences recovers random similarities exactly without noise", "[registration]") {
    std::mt19937 rng(1);
    std::normal_distribution<float> g;
    for (int trial = 0; trial < 20; ++trial) {
        const Similarity T = random_similarity(rng);
        std::vector<float> src, dst;
        for (int i = 0; i < 200; ++i) {
            const Eigen::Vector3d x(g(rng), g(rng), 0.3 * g(rng));
            const Eigen::Vector3d y = T.apply(x);
            for (int c = 0; c < 3; ++c) src.push_back(float(x[c])), dst.push_back(float(y[c]));
        }
        const SimilarityFit fit = similarity_from_correspondences(src.data(), dst.data(), 200);
        CHECK(angle_deg(fit.transform.rotation, T.rotation) < 1e-3);
        CHECK(fit.transform.scale == Approx(T.scale).epsilon(1e-5));
        CHECK((fit.transform.translation - T.translation).norm() < 1e-4 * (1 + T.translation.norm()));
    }
}

TEST_CASE("similarity_from_correspondences: a hand-computed scale and shift", "[registration]") {
    // The unit square's corners and a tetrahedron's apex, doubled and shifted by (1, 2, 3).
    const float src[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    const float dst[] = {1, 2, 3, 3, 2, 3, 1, 4, 3, 1, 2, 5};
    const SimilarityFit fit = similarity_from_correspondences(src, dst, 4);
    CHECK(fit.transform.scale == Approx(2.0).epsilon(1e-12));
    CHECK((fit.transform.rotation - Eigen::Matrix3d::Identity()).norm() < 1e-12);
    CHECK((fit.transform.translation - Eigen::Vector3d(1, 2, 3)).norm() < 1e-12);
}

TEST_CASE("the Cauchy loss rejects gross outliers that bias the plain fit", "[registration]") {
    std::mt19937 rng(2);
    std::normal_distribution<float> g;
    std::uniform_real_distribution<float> u(-5.f, 5.f);
    const Similarity T = random_similarity(rng);
    std::vector<float> src, dst;
    for (int i = 0; i < 1000; ++i) {
        const Eigen::Vector3d x(g(rng), g(rng), g(rng));
        Eigen::Vector3d y = T.apply(x) + 0.001 * Eigen::Vector3d(g(rng), g(rng), g(rng));
        if (i % 5 == 0) y = Eigen::Vector3d(u(rng), u(rng), u(rng));  // 20 % outliers
        for (int c = 0; c < 3; ++c) src.push_back(float(x[c])), dst.push_back(float(y[c]));
    }
    RobustFitOptions plain;
    plain.loss_scale = 0.0;
    const SimilarityFit biased = similarity_from_correspondences(src.data(), dst.data(), 1000, nullptr, plain);
    const SimilarityFit robust = similarity_from_correspondences(src.data(), dst.data(), 1000);
    CHECK(angle_deg(biased.transform.rotation, T.rotation) > 1.0);
    CHECK(angle_deg(robust.transform.rotation, T.rotation) < 0.05);
    CHECK(robust.transform.scale == Approx(T.scale).epsilon(1e-3));
}

TEST_CASE("similarity_from_correspondences refuses degenerate and bad input", "[registration]") {
    const float line[] = {0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0};
    const float other[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    CHECK_THROWS_WITH(similarity_from_correspondences(line, other, 4), Catch::Contains("collinear"));
    CHECK_THROWS_WITH(similarity_from_correspondences(other, other, 2), Catch::Contains("at least 3"));
    const float zero[] = {0, 0, 0, 0};
    CHECK_THROWS_WITH(similarity_from_correspondences(other, other, 4, zero), Catch::Contains("every weight is 0"));
    const float negative[] = {1, 1, -1, 1};
    CHECK_THROWS_WITH(similarity_from_correspondences(other, other, 4, negative), Catch::Contains("weights[2]"));
}

TEST_CASE("the pose graph closes a loop: chained drift is spread over the loop", "[registration]") {
    // Four frames in a loop 0-1-2-3-0; the true transforms are random, the measurements exact
    // except edge 2-3, which carries a scale error of 4 %.
    std::mt19937 rng(3);
    std::vector<Similarity> truth{Similarity{}};
    for (int i = 1; i < 4; ++i) truth.push_back(random_similarity(rng));
    std::vector<PoseGraphEdge> edges;
    for (int i = 0; i < 4; ++i) {
        PoseGraphEdge e;
        e.a = i;
        e.b = (i + 1) % 4;
        e.measured = truth[e.a].inverse() * truth[e.b];
        edges.push_back(e);
    }
    edges[2].measured.scale *= 1.04;
    // Exact measurements give the truth back from a perturbed start.
    std::vector<PoseGraphEdge> exact = edges;
    exact[2].measured = truth[2].inverse() * truth[3];
    std::vector<Similarity> start = truth;
    for (int i = 1; i < 4; ++i) start[i].scale *= 1.1, start[i].translation += Eigen::Vector3d(0.1, -0.2, 0.05);
    const PoseGraphResult r = optimize_pose_graph(exact, start);
    for (int i = 1; i < 4; ++i) {
        CHECK(angle_deg(r.transforms[i].rotation, truth[i].rotation) < 1e-6);
        CHECK(r.transforms[i].scale == Approx(truth[i].scale).epsilon(1e-8));
    }
    CHECK(r.final_cost < 1e-16);
    // With the bad edge, the loop's log-scale error of log 1.04 is shared by the four edges
    // (equal weights; no translations, so that scale is decoupled from them): each edge's scale
    // residual is log(1.04) / 4.
    for (PoseGraphEdge& e : edges) e.measured.translation.setZero();
    std::vector<Similarity> chain{Similarity{}};
    for (int i = 1; i < 4; ++i) chain.push_back(chain.back() * edges[i - 1].measured);
    const PoseGraphResult loop = optimize_pose_graph(edges, chain);
    CHECK(loop.final_cost < loop.initial_cost);
    for (const PoseGraphEdge& e : edges) {
        const Similarity E = e.measured.inverse() * loop.transforms[e.a].inverse() * loop.transforms[e.b];
        CHECK(std::abs(std::log(E.scale)) == Approx(std::log(1.04) / 4).epsilon(1e-4));
    }
    PoseGraphEdge far;
    far.a = 0;
    far.b = 5;
    CHECK_THROWS_WITH(optimize_pose_graph({far}, chain), Catch::Contains("edge 0"));
    CHECK_THROWS_WITH(optimize_pose_graph({edges[0]}, chain), Catch::Contains("node 2 is not connected"));
}

namespace {

SimulatorOptions small_capture(int frames) {
    SimulatorOptions o;
    o.views = frames;
    o.width = 40;
    o.height = 30;
    o.target_views = 2;
    o.supersample = 1;
    return o;
}

}  // namespace

TEST_CASE("align_chunks recovers the true transforms of a simulated chunked capture", "[registration]") {
    ChunkedCaptureOptions k;
    k.window = 12;
    k.overlap = 4;
    const ChunkedCapture cap = simulate_chunked_capture(small_capture(48), k);
    REQUIRE(cap.chunks.size() == 6);  // starts 0, 8, 16, 24, 32 and 36 (the last ends at frame 48)
    std::vector<PredictionChunk> chunks;
    for (std::size_t i = 0; i < cap.chunks.size(); ++i) chunks.push_back(cap.chunks[i].prediction_chunk("w" + std::to_string(i)));
    const ChunkAlignment al = align_chunks(chunks);
    REQUIRE(al.transforms.size() == chunks.size());
    const Similarity world_from_0 = cap.chunks[0].world_from_chunk;
    for (std::size_t i = 1; i < chunks.size(); ++i) {
        // Truth: chunk 0 from chunk i.
        const Similarity truth = world_from_0.inverse() * cap.chunks[i].world_from_chunk;
        CHECK(angle_deg(al.transforms[i].rotation, truth.rotation) < 0.5);
        CHECK(al.transforms[i].scale / truth.scale == Approx(1.0).epsilon(0.01));
        // 1 % of the scene size (about 3 world units, in chunk 0's units).
        CHECK((al.transforms[i].translation - truth.translation).norm() < 0.01 * 3.0 * world_from_0.inverse().scale);
    }
    // Deterministic for any thread count.
    const int threads = omp_get_max_threads();
    omp_set_num_threads(1);
    const ChunkAlignment one = align_chunks(chunks);
    omp_set_num_threads(threads);
    for (std::size_t i = 0; i < chunks.size(); ++i) CHECK(one.transforms[i].matrix() == al.transforms[i].matrix());
}

TEST_CASE("align_chunks names the chunk at fault", "[registration]") {
    ChunkedCaptureOptions k;
    k.window = 8;
    k.overlap = 2;
    const ChunkedCapture cap = simulate_chunked_capture(small_capture(14), k);
    std::vector<PredictionChunk> chunks{cap.chunks[0].prediction_chunk("first"), cap.chunks[1].prediction_chunk("second")};
    // No shared frames.
    std::vector<PredictionChunk> apart = chunks;
    for (auto& id : apart[1].frame_ids) id += 100;
    CHECK_THROWS_WITH(align_chunks(apart), Catch::Contains("chunk 1 ('second') shares no frames"));
    // No valid pixel.
    std::vector<PredictionChunk> empty = chunks;
    std::fill(empty[1].valid.begin(), empty[1].valid.end(), 0);
    CHECK_THROWS_WITH(align_chunks(empty), Catch::Contains("chunk 'second': no valid pixel"));
    // Degenerate geometry: every shared point on one line.
    std::vector<PredictionChunk> line = chunks;
    for (std::size_t i = 0; i < line[1].points.size(); i += 3) line[1].points[i + 1] = line[1].points[i + 2] = 0.f;
    CHECK_THROWS_WITH(align_chunks(line), Catch::Contains("chunk 0 ('first') and chunk 1 ('second')") &&
                                              Catch::Contains("degenerate"));
}

TEST_CASE("stitch fuses aligned chunks into chunk 0's frame, and streams the same result", "[registration]") {
    ChunkedCaptureOptions k;
    k.window = 10;
    k.overlap = 4;
    const ChunkedCapture cap = simulate_chunked_capture(small_capture(22), k);
    std::vector<PredictionChunk> chunks;
    for (const CaptureChunk& c : cap.chunks) chunks.push_back(c.prediction_chunk());
    const StitchResult r = stitch(chunks, 0.02 / cap.chunks[0].world_from_chunk.scale);
    CHECK(r.cloud.size() > 0);
    CHECK(r.cloud.size() < r.input_gaussians);
    StitchOptions streamed;
    streamed.memory_limit = 1 << 20;
    const StitchResult s = stitch(chunks, 0.02 / cap.chunks[0].world_from_chunk.scale, FusionParams{}, streamed);
    REQUIRE(s.cloud.size() == r.cloud.size());
    CHECK(s.cloud.means == r.cloud.means);
    StitchOptions concat;
    concat.fuse = false;
    const StitchResult c = stitch(chunks, 1.0, FusionParams{}, concat);
    CHECK(c.cloud.size() == c.input_gaussians);
    std::vector<Similarity> wrong(chunks.size() - 1);
    CHECK_THROWS_WITH(fuse_chunks(chunks, wrong, 1.0), Catch::Contains("transforms for"));
}
