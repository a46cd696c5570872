// The CPU renderer's projection stage: for each Gaussian of a range, its splat record
// (preprocess::project_record, project_and_shade.h), its power_cut (tile_state.h) and its sort key
// (tiling::depth_index_key), or kCulledKey when it is culled.
//
// project_one is the reference: project_record, then power_cutoff and the key, one Gaussian at a
// time (the float64 frames and the portable kernel run it). project_splats runs float32 ranges in
// blocks of 8 Gaussians across vector lanes (project_block.h, compiled for AVX2 and AVX-512 in
// project_block_avx2.cpp and project_block_avx512.cpp) where `kernel` says so: the same IEEE
// operations in the same order as project_record, so every record, power_cut and key, culling
// decisions included, is the reference's bit for bit (tests/cpp/test_project_splats.cpp), and
// the CPU records stay those of the CUDA renderer, which calls project_record itself.
#pragma once

#include "avsplat/core/gaussians.h"
#include "render/cpu/cpu_kernel.h"
#include "render/cpu/tile_state.h"
#include "render/shared/project_and_shade.h"

#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace avsplat::detail::cpu {

/// The key of a culled Gaussian. No visible key equals it: its index part 2^32 - 1 exceeds every
/// Gaussian index (render() admits at most 2^32 - 1 Gaussians).
constexpr std::uint64_t kCulledKey = ~std::uint64_t(0);

/// Gaussian i of `cloud`: writes rec (project_record; power_cut as well for float records, which
/// the vector tile kernels read) and key = depth_index_key(depth, i), or key = kCulledKey, leaving
/// rec unspecified, when the Gaussian is culled. `alpha_threshold` is RenderOptions'.
template <class T>
inline void project_one(const preprocess::ViewParams<T>& view, const GaussianCloud& cloud, T alpha_threshold,
                        std::int64_t i, SplatRecord<T>& rec, std::uint64_t& key) {
    const std::size_t k = std::size_t(i);
    const std::uint32_t n_tiles =
        preprocess::project_record(view, &cloud.means[3 * k], &cloud.scales[3 * k], &cloud.rotations[4 * k],
                                   cloud.opacities[k], &cloud.sh[k * std::size_t(cloud.sh_coeffs()) * 3], rec);
    if (n_tiles == 0) {
        key = kCulledKey;
        return;
    }
    if constexpr (std::is_same_v<T, float>) rec.power_cut = power_cutoff(rec, alpha_threshold);
    key = tiling::depth_index_key(float(rec.depth), std::uint32_t(i));
}

/// project_one for each Gaussian i in [begin, end) of `cloud`, into splats[i] and keys[i], with
/// the vector kernel `kernel` names where this build and CPU have it (Portable: project_one
/// itself). The same results for every kernel. Expects a validated cloud and the view of
/// preprocess::view_params<float>.
void project_splats(CpuKernel kernel, const preprocess::ViewParams<float>& view, const GaussianCloud& cloud,
                    float alpha_threshold, std::int64_t begin, std::int64_t end, SplatRecord<float>* splats,
                    std::uint64_t* keys);

}  // namespace avsplat::detail::cpu
