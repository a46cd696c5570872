#include "render/cpu/project_splats.h"

#include "render/cpu/project_block_kernels.h"

namespace avsplat::detail::cpu {

void power_cut_scalar(SplatRecord<float>& rec, float alpha_threshold) {
    rec.power_cut = power_cutoff(rec, alpha_threshold);
}

void project_splats(CpuKernel kernel, const preprocess::ViewParams<float>& view, const GaussianCloud& cloud,
                    float alpha_threshold, std::int64_t begin, std::int64_t end, SplatRecord<float>* splats,
                    std::uint64_t* keys) {
    std::int64_t i = begin;
    const std::int64_t blocks = kernel == CpuKernel::Portable ? 0 : (end - begin) / kProjectLanes;
    if (kernel == CpuKernel::Avx512)
        project_blocks_avx512(view, cloud, alpha_threshold, begin, blocks, splats, keys);
    else if (kernel == CpuKernel::Avx2)
        project_blocks_avx2(view, cloud, alpha_threshold, begin, blocks, splats, keys);
    i += blocks * kProjectLanes;
    for (; i < end; ++i) project_one(view, cloud, alpha_threshold, i, splats[i], keys[i]);
}

}  // namespace avsplat::detail::cpu
