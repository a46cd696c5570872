// Pairwise similarity estimates from shared frames, then the pose graph (or a chain).
#include "avsplat/registration/chunk_alignment.h"

#include "core/confidence_mapping.h"

#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

namespace {

struct Correspondences {
    std::vector<float> a, b;  // n x 3 each
    std::vector<float> weight;
};

float pixel_weight(const PredictionChunk& c, std::size_t i) {
    return c.confidence.empty() ? 1.f : confidence::confidence_probability<float>(c.confidence[i], c.confidence_mapping);
}

// The same pixel of every frame both chunks hold, valid in both.
Correspondences shared_pixels(const PredictionChunk& ca, const PredictionChunk& cb) {
    Correspondences out;
    if (ca.height != cb.height || ca.width != cb.width) return out;
    std::map<std::int64_t, int> view_of;
    for (int s = 0; s < cb.views; ++s) view_of[cb.frame_ids[s]] = s;
    const std::size_t per_view = std::size_t(ca.height) * ca.width;
    for (int sa = 0; sa < ca.views; ++sa) {
        const auto it = view_of.find(ca.frame_ids[sa]);
        if (it == view_of.end()) continue;
        const std::size_t oa = sa * per_view, ob = std::size_t(it->second) * per_view;
        for (std::size_t p = 0; p < per_view; ++p) {
            const std::size_t ia = oa + p, ib = ob + p;
            if ((!ca.valid.empty() && !ca.valid[ia]) || (!cb.valid.empty() && !cb.valid[ib])) continue;
            const float w = pixel_weight(ca, ia) * pixel_weight(cb, ib);
            if (!(w > 0.f)) continue;
            for (int c = 0; c < 3; ++c) {
                out.a.push_back(ca.points[3 * ia + c]);
                out.b.push_back(cb.points[3 * ib + c]);
            }
            out.weight.push_back(w);
        }
    }
    return out;
}

}  // namespace

ChunkAlignment align_chunks(const std::vector<PredictionChunk>& chunks, const AlignmentOptions& options) {
    if (chunks.empty()) throw std::invalid_argument("align_chunks: no chunks");
    if (options.min_correspondences < 3) throw std::invalid_argument("align_chunks: min_correspondences must be >= 3");
    for (const PredictionChunk& c : chunks) c.validate();
    const int n = static_cast<int>(chunks.size());
    auto label = [&](int i) {
        return "chunk " + std::to_string(i) + (chunks[i].name.empty() ? "" : " ('" + chunks[i].name + "')");
    };

    ChunkAlignment result;
    std::vector<Correspondences> kept;
    std::vector<SimilarityFit> fits;
    for (int a = 0; a < n; ++a) {
        for (int b = a + 1; b < n; ++b) {
            Correspondences cs = shared_pixels(chunks[a], chunks[b]);
            if (cs.weight.size() < std::size_t(options.min_correspondences)) continue;
            SimilarityFit fit;
            try {
                fit = similarity_from_correspondences(cs.b.data(), cs.a.data(), cs.weight.size(), cs.weight.data(),
                                                      options.fit);
            } catch (const std::invalid_argument& e) {
                throw std::invalid_argument("align_chunks: " + label(a) + " and " + label(b) + ": " + e.what());
            }
            PairAlignment p;
            p.a = a;
            p.b = b;
            p.a_from_b = fit.transform;
            p.correspondences = cs.weight.size();
            p.rms_residual = fit.rms_residual;
            p.scene_size = fit.scene_size;
            result.pairs.push_back(p);
            fits.push_back(fit);
            kept.push_back(std::move(cs));
        }
    }

    // The chain: breadth-first from chunk 0, neighbours in chunk order.
    std::vector<std::vector<int>> incident(n);
    for (std::size_t k = 0; k < result.pairs.size(); ++k) {
        incident[result.pairs[k].a].push_back(static_cast<int>(k));
        incident[result.pairs[k].b].push_back(static_cast<int>(k));
    }
    std::vector<Similarity> T(n);
    std::vector<char> reached(n, 0);
    std::vector<int> queue{0};
    reached[0] = 1;
    for (std::size_t q = 0; q < queue.size(); ++q) {
        const int u = queue[q];
        for (int k : incident[u]) {
            const PairAlignment& p = result.pairs[k];
            const int v = p.a == u ? p.b : p.a;
            if (reached[v]) continue;
            reached[v] = 1;
            // T_v = T_u M (v = b) or T_u M^-1 (v = a), M = a_from_b.
            T[v] = p.a == u ? T[u] * p.a_from_b : T[u] * p.a_from_b.inverse();
            queue.push_back(v);
        }
    }
    for (int i = 0; i < n; ++i)
        if (!reached[i])
            throw std::invalid_argument("align_chunks: " + label(i) + " shares no frames (at least " +
                                        std::to_string(options.min_correspondences) +
                                        " valid pixels in common) with the chunks connected to chunk 0");

    if (options.pose_graph) {
        std::vector<PoseGraphEdge> edges;
        for (std::size_t k = 0; k < result.pairs.size(); ++k) {
            const PairAlignment& p = result.pairs[k];
            PoseGraphEdge e;
            e.a = p.a;
            e.b = p.b;
            e.measured = p.a_from_b;
            // The estimate's precision: effective count over the squared residual relative to
            // the scene size; the translation error is measured in units of the scene size.
            e.length = std::max(p.scene_size / p.a_from_b.scale, 1e-300);
            const double rel = std::max(p.rms_residual / std::max(p.scene_size, 1e-300), 1e-9);
            e.weight = std::max(fits[k].effective_count, 1.0) / (rel * rel);
            edges.push_back(e);
        }
        const PoseGraphResult g = optimize_pose_graph(edges, T);
        T = g.transforms;
        result.initial_cost = g.initial_cost;
        result.final_cost = g.final_cost;
    }
    result.transforms = T;

    // Residuals after alignment, in chunk 0's units.
    result.residuals.assign(n, 0.0);
    std::vector<double> sum(n, 0.0);
    std::vector<int> count(n, 0);
    for (std::size_t k = 0; k < result.pairs.size(); ++k) {
        PairAlignment& p = result.pairs[k];
        const Correspondences& cs = kept[k];
        const double kk = options.fit.loss_scale * p.scene_size;
        double wsum = 0.0, r2 = 0.0;
        for (std::size_t i = 0; i < cs.weight.size(); ++i) {
            const Eigen::Vector3d xa(cs.a[3 * i], cs.a[3 * i + 1], cs.a[3 * i + 2]);
            const Eigen::Vector3d xb(cs.b[3 * i], cs.b[3 * i + 1], cs.b[3 * i + 2]);
            const double d_pair = (xa - p.a_from_b.apply(xb)).norm();
            const double w = kk > 0.0 ? cs.weight[i] / (1.0 + (d_pair / kk) * (d_pair / kk)) : cs.weight[i];
            const double d = (T[p.a].apply(xa) - T[p.b].apply(xb)).norm();
            wsum += w;
            r2 += w * d * d;
        }
        p.aligned_rms = wsum > 0.0 ? std::sqrt(r2 / wsum) : 0.0;
        for (int node : {p.a, p.b}) {
            sum[node] += p.aligned_rms * p.aligned_rms;
            ++count[node];
        }
    }
    for (int i = 0; i < n; ++i) result.residuals[i] = count[i] ? std::sqrt(sum[i] / count[i]) : 0.0;
    return result;
}

}  // namespace avsplat
