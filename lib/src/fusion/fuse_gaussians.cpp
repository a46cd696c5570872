// fuse_gaussians: one fused Gaussian per occupied voxel, with the shape modes (ShapeMode) that
// combine the scales and rotations.
#include "avsplat/fusion/fusion.h"

#include "core/interrupt_poll.h"
#include "core/progress_report.h"
#include "common/parallel.h"
#include "core/gaussian_validity.h"
#include "core/invalid_samples.h"
#include "fusion/block_weigher.h"
#include "fusion/checks.h"
#include "fusion/weighted_rows.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

namespace avsplat {

namespace {

using namespace fusion_detail;

// Unit quaternion (w, x, y, z) with w >= 0 stored as float.
void store_quaternion(Eigen::Vector4d q, float* out) {
    q.normalize();
    if (q[0] < 0.0) q = -q;
    for (int a = 0; a < 4; ++a) out[a] = float(q[a]);
}

template <class T>
void fuse_gaussians_pass(const SparseVoxelGrid& grid, const TieFields& ties, const GaussianCloud& in,
                         const FusionParams& p, GaussianFusionResult& result, ProgressReport& report) {
    const std::size_t m = grid.num_voxels();
    const std::size_t k3 = std::size_t(in.sh_coeffs()) * 3;
    GaussianCloud& out = result.cloud;
    out = GaussianCloud(m, in.sh_degree);
    if (in.has_confidence()) out.confidence.resize(m);
    out.extras.clear();
    for (const auto& e : in.extras) out.extras.push_back({e.name, std::vector<float>(m)});
    allocate_diagnostics(result.diagnostics, m);
    const float* conf_in = in.has_confidence() ? in.confidence.data() : nullptr;
    const std::int64_t* offsets = grid.voxel_offsets().data();
    const std::int64_t blocks = std::int64_t((m + kBlockVoxels - 1) / kBlockVoxels);
    InterruptPoll poll;
    // Progress in samples fused, reported after each of up to kProgressSlices equal runs of blocks by
    // the calling thread (the master), while the others go on: the same reports for every
    // thread count. An exception from the callback stops the loop like an interrupt.
    // Without a callback one run, as before; with one, runs of at least 16 blocks, so that the
    // barrier between runs costs little.
    const std::int64_t slices =
        report.active() ? std::clamp<std::int64_t>(blocks / 16, 1, kProgressSlices) : std::int64_t(1);
    const auto slice_begin = [&](std::int64_t s) { return blocks * s / slices; };
    const auto samples_before = [&](std::int64_t block) {
        return std::uint64_t(offsets[std::min(m, std::size_t(block) * kBlockVoxels)] - offsets[0]);
    };
#pragma omp parallel if (grid.sample_indices().size() >= kParallelMin)
    {
        std::optional<BlockWeigher<T>> weigher;
        std::vector<double> wd, extra_acc;
        poll.guard([&] {  // std::bad_alloc stops the loop and is rethrown after the region
            weigher.emplace(grid, ties, p, in.means.data(), conf_in);
            extra_acc.resize(in.extras.size());
        });
        for (std::int64_t slice = 0; slice < slices; ++slice) {
#pragma omp master
            if (slice > 0 && !poll.stopped()) poll.guard([&] { report.set(samples_before(slice_begin(slice))); });
#pragma omp for schedule(dynamic, 2)
            for (std::int64_t block = slice_begin(slice); block < slice_begin(slice + 1); ++block) {
                if (poll.stop() || !weigher) continue;
                poll.guard([&] {
                    const std::size_t v0 = std::size_t(block) * kBlockVoxels, v1 = std::min(m, v0 + kBlockVoxels);
                    weigher->run(v0, v1);
                    for (std::size_t v = v0; v < v1; ++v) {
                        const std::int64_t b = offsets[v];
                        const std::size_t n = std::size_t(offsets[v + 1] - b);
                        store_diagnostics(result.diagnostics, v, n, weigher->stats(v));
                        if (n == 1) {
                            const std::size_t i = std::size_t(weigher->ids(v)[0]);
                            std::copy_n(&in.means[3 * i], 3, &out.means[3 * v]);
                            std::copy_n(&in.scales[3 * i], 3, &out.scales[3 * v]);
                            std::copy_n(&in.rotations[4 * i], 4, &out.rotations[4 * v]);
                            out.opacities[v] = in.opacities[i];
                            std::copy_n(in.sh.data() + k3 * i, k3, out.sh.data() + k3 * v);
                            if (in.has_confidence()) out.confidence[v] = in.confidence[i];
                            for (std::size_t e = 0; e < in.extras.size(); ++e) out.extras[e].values[v] = in.extras[e].values[i];
                            continue;
                        }
                        const std::int32_t* ids = weigher->ids(v);
                        const T* w = weigher->weights(v);
                        // The samples that trimming left out (weight 0) are the voxel's last ones; every
                        // sample is valid, so they change no sum (which starts at +0) and are not read.
                        std::size_t used = n;
                        while (used > 1 && w[used - 1] == T(0)) --used;
                        wd.resize(used);
                        double wsum = 0.0, opacity = 0.0, conf = 0.0;
                        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
                        std::fill(extra_acc.begin(), extra_acc.end(), 0.0);
                        std::size_t leader = 0;  // highest weight, first in canonical order on ties
                        for (std::size_t k = 0; k < used; ++k) {
                            const double wk = wd[k] = double(w[k]);
                            if (w[k] > w[leader]) leader = k;
                            const std::size_t i = std::size_t(ids[k]);
                            wsum += wk;
                            mean += wk * in.mean(i).cast<double>();
                            opacity += wk * double(in.opacities[i]);
                            if (in.has_confidence()) conf += wk * double(in.confidence[i]);
                            for (std::size_t e = 0; e < in.extras.size(); ++e) extra_acc[e] += wk * double(in.extras[e].values[i]);
                        }
                        const double inv = 1.0 / wsum;
                        mean *= inv;
                        for (int a = 0; a < 3; ++a) out.means[3 * v + a] = float(mean[a]);
                        out.opacities[v] = float(std::min(1.0, std::max(0.0, opacity * inv)));
                        if (in.has_confidence()) out.confidence[v] = float(conf * inv);
                        weighted_rows(in.sh.data(), k3, ids, wd.data(), used, inv, out.sh.data() + k3 * v);
                        for (std::size_t e = 0; e < in.extras.size(); ++e) out.extras[e].values[v] = float(extra_acc[e] * inv);

                        if (p.shape == ShapeMode::Moment) {
                            Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();
                            for (std::size_t k = 0; k < n; ++k) {
                                if (!(w[k] > T(0))) continue;
                                const std::size_t i = std::size_t(ids[k]);
                                const Eigen::Vector3d d = in.mean(i).cast<double>() - mean;
                                sigma += double(w[k]) * (in.covariance(i) + d * d.transpose());
                            }
                            sigma *= inv;
                            const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sigma);
                            Eigen::Matrix3d r = eig.eigenvectors();
                            if (r.determinant() < 0.0) r.col(0) = -r.col(0);
                            const Eigen::Quaterniond q(r);
                            for (int a = 0; a < 3; ++a) out.scales[3 * v + a] = float(std::sqrt(std::max(0.0, eig.eigenvalues()[a])));
                            store_quaternion(Eigen::Vector4d(q.w(), q.x(), q.y(), q.z()), &out.rotations[4 * v]);
                        } else {
                            // Weighted geometric mean of the scales (log 0 = -inf gives 0, never NaN: zero
                            // weights are skipped) and the hemisphere-aligned quaternion mean.
                            Eigen::Vector3d log_scale = Eigen::Vector3d::Zero();
                            Eigen::Vector4d quat = Eigen::Vector4d::Zero();
                            const Eigen::Vector4d ref = in.rotation(std::size_t(ids[leader])).cast<double>().normalized();
                            for (std::size_t k = 0; k < n; ++k) {
                                if (!(w[k] > T(0))) continue;
                                const std::size_t i = std::size_t(ids[k]);
                                const double wk = double(w[k]);
                                for (int a = 0; a < 3; ++a) log_scale[a] += wk * std::log(double(in.scales[3 * i + a]));
                                Eigen::Vector4d q = in.rotation(i).cast<double>().normalized();
                                if (q.dot(ref) < 0.0) q = -q;
                                quat += wk * q;
                            }
                            for (int a = 0; a < 3; ++a) out.scales[3 * v + a] = float(std::exp(log_scale[a] * inv));
                            store_quaternion(quat, &out.rotations[4 * v]);
                        }
                    }
                });
            }
        }
    }
    poll.throw_if_stopped();
    report.finish();
}

template <class T>
GaussianFusionResult fuse_cloud(const GaussianCloud& cloud, double voxel_size, const FusionParams& p) {
    check_cloud_shapes(cloud);
    const std::size_t n = cloud.size();
    ProgressReport report(n);  // samples; dropped ones count as done at the end
    std::vector<std::uint8_t> keep;
    // Raise: validate() names the first invalid Gaussian's field and defect. Drop: the same rule
    // per Gaussian (core/gaussian_validity.h).
    const auto bad = [&](std::size_t i) {
        GaussianField field = GaussianField::Means;
        return check_gaussian(cloud, i, field) != GaussianDefect::None;
    };
    apply_invalid_policy(n, bad, p.on_invalid, keep, [&](std::size_t) { validate(cloud); });
    const float* conf = cloud.has_confidence() ? cloud.confidence.data() : nullptr;
    check_confidence(conf, n, p, "GaussianCloud.confidence", keep);

    TieFields ties;
    ties.push_back({cloud.opacities.data(), 1});
    ties.push_back({cloud.scales.data(), 3});
    ties.push_back({cloud.rotations.data(), 4});
    ties.push_back({cloud.sh.data(), std::size_t(cloud.sh_coeffs()) * 3});
    for (const auto& e : cloud.extras) ties.push_back({e.values.data(), 1});

    SparseVoxelGrid grid(cloud.means.data(), n, voxel_size, p.on_invalid, keep.empty() ? nullptr : keep.data(),
                         "GaussianCloud.means");
    GaussianFusionResult result;
    fuse_gaussians_pass<T>(grid, ties, cloud, p, result, report);
    result.dropped = grid.dropped();
    result.voxel_coords = std::move(grid).voxel_coords();
    result.sample_voxel = std::move(grid).sample_voxel();
    return result;
}

}  // namespace

GaussianFusionResult fuse_gaussians(const GaussianCloud& cloud, double voxel_size, const FusionParams& params) {
    validate(params);
    if (params.precision == Precision::Float64) return fuse_cloud<double>(cloud, voxel_size, params);
    return fuse_cloud<float>(cloud, voxel_size, params);
}

}  // namespace avsplat
