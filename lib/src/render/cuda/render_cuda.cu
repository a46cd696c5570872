// The CUDA renderer's kernels and their orchestration, one translation unit so that the five
// target architectures compile the kernels and CUB once.
//
// A frame, all on one stream:
//   1. project:  one thread per Gaussian (kernel_bodies.h project_record) -> splat records and the
//                number of tiles each one meets (0 = culled);
//   2. scan:     CUB inclusive sum of the counts -> where each Gaussian's keys go;
//   3. emit:     one thread per Gaussian writes (tile << 32 | depth bits, index) pairs in
//                index order (write_tile_keys);
//   4. sort:     CUB radix sort of the pairs (stable), on the key bits that can be non-zero,
//                giving tile, then depth, then index order;
//   5. ranges:   one thread per instance finds where each tile's run starts and ends;
//   6. blend:    one 16 x 16 block per tile, one thread per pixel; the tile's splats are staged
//                in shared memory 256 at a time (one load per thread) and every thread walks the
//                batch front to back (composite); a block stops as soon as all its pixels are
//                saturated (__syncthreads_count), and each thread skips the rest once its own
//                pixel is.
// The per-thread bodies are the host-callable functions of kernel_bodies.h; this file only indexes,
// allocates and launches. Every CUDA call is checked and a failure becomes avsplat::DeviceError
// with the CUDA error string.
#include "render/cuda/render_frame.h"

#include "avsplat/core/error.h"

#include <cub/block/block_reduce.cuh>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda_runtime.h>

#include <chrono>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

namespace avsplat::gpu {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

/// Throws DeviceError naming `what` with the CUDA error string when `e` is not cudaSuccess.
void check(cudaError_t e, const char* what) {
    if (e != cudaSuccess) {
        (void)cudaGetLastError();  // clear a non-sticky error so that later calls can succeed
        throw DeviceError(std::string("CUDA renderer: ") + what + ": " + cudaGetErrorString(e));
    }
}

/// Checks a kernel launch (configuration errors are reported at launch, faults at the next sync).
void check_launch(const char* kernel) { check(cudaGetLastError(), kernel); }

/// An owned device allocation of `count` elements of U (none for count 0), freed on scope exit.
template <class U>
class DeviceBuffer {
public:
    DeviceBuffer() = default;
    DeviceBuffer(std::uint64_t count, const char* what) : count_(count) {
        if (count == 0) return;
        const std::uint64_t bytes = count * sizeof(U);
        const cudaError_t e = cudaMalloc(reinterpret_cast<void**>(&ptr_), std::size_t(bytes));
        if (e != cudaSuccess) {
            ptr_ = nullptr;
            (void)cudaGetLastError();
            throw DeviceError("CUDA renderer: cudaMalloc of " + std::to_string(bytes) +
                              " bytes for " + what + ": " + cudaGetErrorString(e));
        }
    }
    DeviceBuffer(const DeviceBuffer&) = delete;
    DeviceBuffer& operator=(const DeviceBuffer&) = delete;
    DeviceBuffer(DeviceBuffer&& o) noexcept : ptr_(std::exchange(o.ptr_, nullptr)), count_(o.count_) {}
    DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
        std::swap(ptr_, o.ptr_);
        std::swap(count_, o.count_);
        return *this;
    }
    ~DeviceBuffer() {
        if (ptr_) cudaFree(ptr_);  // a failure here cannot be reported; the memory is gone anyway
    }
    U* get() const { return ptr_; }
    std::uint64_t size() const { return count_; }

private:
    U* ptr_ = nullptr;
    std::uint64_t count_ = 0;
};

/// Copies `count` elements from the host to a new device buffer.
template <class U>
DeviceBuffer<U> upload(const U* host, std::uint64_t count, const char* what) {
    DeviceBuffer<U> d(count, what);
    if (count) check(cudaMemcpy(d.get(), host, count * sizeof(U), cudaMemcpyHostToDevice), what);
    return d;
}

/// The device arrays of a frame's Gaussians, uploaded from the host when needed.
struct ResidentGaussians {
    GaussianArrays view;  ///< device pointers
    DeviceBuffer<float> means, scales, rotations, opacities, sh;
};

ResidentGaussians make_resident(const GaussianArrays& g) {
    ResidentGaussians r;
    r.view = g;
    if (g.on_device) return r;
    const std::uint64_t k = sh_floats(g.sh_degree);
    r.means = upload(g.means, 3 * g.size, "uploading means");
    r.scales = upload(g.scales, 3 * g.size, "uploading scales");
    r.rotations = upload(g.rotations, 4 * g.size, "uploading rotations");
    r.opacities = upload(g.opacities, g.size, "uploading opacities");
    r.sh = upload(g.sh, k * g.size, "uploading sh");
    r.view.means = r.means.get();
    r.view.scales = r.scales.get();
    r.view.rotations = r.rotations.get();
    r.view.opacities = r.opacities.get();
    r.view.sh = r.sh.get();
    r.view.on_device = true;
    return r;
}

// ---- kernels --------------------------------------------------------------------------------

__device__ std::uint64_t thread_index() {
    return std::uint64_t(blockIdx.x) * blockDim.x + threadIdx.x;
}

__global__ void __launch_bounds__(kThreadsPerBlock)
validate_kernel(GaussianArrays g, int k, unsigned long long* first_bad) {
    const std::uint64_t i = thread_index();
    if (i >= g.size) return;
    Field field;
    if (check_gaussian(g.means + 3 * i, g.scales + 3 * i, g.rotations + 4 * i, g.opacities[i],
                       g.sh + i * std::uint64_t(k), k, field) != Invalid::None)
        atomicMin(first_bad, static_cast<unsigned long long>(i));
}

template <class T>
__global__ void __launch_bounds__(kThreadsPerBlock)
project_kernel(GaussianArrays g, std::uint64_t k, ViewParams<T> view, SplatRecord<T>* records,
               std::uint64_t* counts, unsigned long long* visible) {
    const std::uint64_t i = thread_index();
    std::uint32_t tiles = 0;
    if (i < g.size) {
        SplatRecord<T> rec;
        tiles = project_record(view, g.means + 3 * i, g.scales + 3 * i, g.rotations + 4 * i,
                               g.opacities[i], g.sh + k * i, rec);
        if (tiles) records[i] = rec;
        counts[i] = tiles;
    }
    const int block_visible = __syncthreads_count(tiles > 0);
    if (threadIdx.x == 0 && block_visible > 0)
        atomicAdd(visible, static_cast<unsigned long long>(block_visible));
}

template <class T>
__global__ void __launch_bounds__(kThreadsPerBlock)
emit_kernel(std::uint64_t n, const SplatRecord<T>* records, const std::uint64_t* counts,
            const std::uint64_t* ends, int tiles_x, std::uint64_t* keys, std::uint32_t* values) {
    const std::uint64_t i = thread_index();
    if (i >= n || counts[i] == 0) return;
    const std::uint64_t first = ends[i] - counts[i];
    write_tile_keys(records[i], std::uint32_t(i), tiles_x, keys + first, values + first);
}

__global__ void __launch_bounds__(kThreadsPerBlock)
ranges_kernel(const std::uint64_t* sorted_keys, std::uint32_t n, std::uint32_t* starts,
              std::uint32_t* ends) {
    const std::uint64_t i = thread_index();
    if (i < n) mark_tile_range(sorted_keys, std::uint32_t(i), n, starts, ends);
}

template <class T>
__global__ void __launch_bounds__(kBlockPixels)
blend_kernel(const std::uint32_t* sorted_values, const std::uint32_t* starts,
             const std::uint32_t* ends, const SplatRecord<T>* records, FramePlan plan,
             BlendParams<T> bp, float* color, float* alpha, float* depth,
             std::int32_t* contributors, unsigned long long* totals) {
    constexpr int kTile = tiling::kTileSize;
    using Reduce = cub::BlockReduce<unsigned long long, kTile, cub::BLOCK_REDUCE_WARP_REDUCTIONS, kTile>;
    __shared__ SplatRecord<T> batch[kBlockPixels];
    __shared__ typename Reduce::TempStorage reduce_storage;

    const int x = int(blockIdx.x) * kTile + int(threadIdx.x);
    const int y = int(blockIdx.y) * kTile + int(threadIdx.y);
    const int lane = int(threadIdx.y) * kTile + int(threadIdx.x);
    const bool inside = x < plan.width && y < plan.height;
    const std::uint32_t tile = blockIdx.y * std::uint32_t(plan.tiles_x) + blockIdx.x;
    const std::uint32_t begin = starts[tile], end = ends[tile];
    const T px = T(x) + T(0.5), py = T(y) + T(0.5);
    PixelState<T> p = pixel_start<T>(inside);

    for (std::uint32_t first = begin; first < end; first += kBlockPixels) {
        // Also the barrier that keeps the previous batch until every thread has finished it.
        if (__syncthreads_count(p.done) == kBlockPixels) break;
        if (first + std::uint32_t(lane) < end) batch[lane] = records[sorted_values[first + lane]];
        __syncthreads();
        const std::uint32_t count = end - first < std::uint32_t(kBlockPixels) ? end - first : kBlockPixels;
        for (std::uint32_t j = 0; j < count && !p.done; ++j) composite(p, batch[j], x, y, px, py, bp);
    }

    if (inside) {
        const std::size_t pix = std::size_t(y) * std::size_t(plan.width) + std::size_t(x);
        float rgb[3];
        finish(p, bp, rgb, alpha[pix], depth[pix]);
        color[3 * pix] = rgb[0];
        color[3 * pix + 1] = rgb[1];
        color[3 * pix + 2] = rgb[2];
        contributors[pix] = p.contributors;
    }
    const unsigned long long evaluated = Reduce(reduce_storage).Sum(static_cast<unsigned long long>(p.evaluated));
    __syncthreads();  // reduce_storage is reused
    const unsigned long long blended = Reduce(reduce_storage).Sum(static_cast<unsigned long long>(p.contributors));
    if (lane == 0) {
        atomicAdd(&totals[0], evaluated);
        atomicAdd(&totals[1], blended);
    }
}

/// Waits for the stream and reports a fault of the stage's kernels.
void sync(cudaStream_t stream, const char* stage) { check(cudaStreamSynchronize(stream), stage); }

}  // namespace

void require_device() {
    int n = 0;
    const cudaError_t e = cudaGetDeviceCount(&n);
    if (e != cudaSuccess) {
        (void)cudaGetLastError();
        throw DeviceError(std::string("no CUDA device: ") + cudaGetErrorString(e));
    }
    if (n == 0) throw DeviceError("no CUDA device: cudaGetDeviceCount found 0 devices");
}

int device_count() noexcept {
    int n = 0;
    if (cudaGetDeviceCount(&n) != cudaSuccess) {
        (void)cudaGetLastError();
        return 0;
    }
    return n;
}

void check_device_pointer(const void* ptr, const char* field) {
    int device = 0;
    check(cudaGetDevice(&device), "cudaGetDevice");
    cudaPointerAttributes a{};
    const cudaError_t e = cudaPointerGetAttributes(&a, ptr);
    if (e != cudaSuccess) (void)cudaGetLastError();
    const bool ok = e == cudaSuccess &&
                    ((a.type == cudaMemoryTypeDevice && a.device == device) ||
                     a.type == cudaMemoryTypeManaged);
    if (!ok)
        throw std::invalid_argument(std::string("DeviceGaussians.") + field +
                                    ": not device memory of device " + std::to_string(device));
}

void validate_on_device(const GaussianArrays& g) {
    if (g.size == 0) return;
    const int k = int(sh_floats(g.sh_degree));
    DeviceBuffer<unsigned long long> first_bad(1, "the validation result");
    const unsigned long long none = std::numeric_limits<unsigned long long>::max();
    check(cudaMemcpy(first_bad.get(), &none, sizeof none, cudaMemcpyHostToDevice), "clearing the validation result");
    validate_kernel<<<grid_blocks(g.size), kThreadsPerBlock>>>(g, k, first_bad.get());
    check_launch("validate kernel");
    unsigned long long bad = none;
    check(cudaMemcpy(&bad, first_bad.get(), sizeof bad, cudaMemcpyDeviceToHost), "validating the Gaussians");
    if (bad == none) return;
    // Read the first bad Gaussian back and name its problem with the same check on the host.
    float mean[3], scale[3], quat[4], opacity;
    float sh[48];
    const auto get = [](float* dst, const float* src, std::uint64_t count) {
        check(cudaMemcpy(dst, src, count * sizeof(float), cudaMemcpyDeviceToHost), "reading an invalid Gaussian");
    };
    get(mean, g.means + 3 * bad, 3);
    get(scale, g.scales + 3 * bad, 3);
    get(quat, g.rotations + 4 * bad, 4);
    get(&opacity, g.opacities + bad, 1);
    get(sh, g.sh + std::uint64_t(k) * bad, std::uint64_t(k));
    Field field = Field::Means;
    const Invalid why = check_gaussian(mean, scale, quat, opacity, sh, k, field);
    throw std::invalid_argument(invalid_message(bad, field, why));
}

template <class T>
FrameStats render_frame(const GaussianArrays& input, const ViewParams<T>& view,
                        const BlendParams<T>& blend, const FramePlan& plan, const FrameOutput& out) {
    // The legacy default stream: it waits for work queued on blocking streams before the call,
    // which is what makes device inputs written by the caller safe to read.
    const cudaStream_t stream = 0;
    FrameStats stats;
    const ResidentGaussians g = make_resident(input);
    const std::uint64_t n = g.view.size;
    const FrameSizes sizes = frame_sizes(plan, n, g.view.sh_degree);

    DeviceBuffer<SplatRecord<T>> records(sizes.gaussians, "splat records");
    DeviceBuffer<std::uint64_t> counts(sizes.gaussians, "tile counts");
    DeviceBuffer<std::uint64_t> ends(sizes.gaussians, "key offsets");
    DeviceBuffer<unsigned long long> counters(3, "counters");  // visible, blends, contributions
    DeviceBuffer<std::uint32_t> tile_starts(sizes.tiles, "tile ranges");
    DeviceBuffer<std::uint32_t> tile_ends(sizes.tiles, "tile ranges");
    DeviceBuffer<float> d_color(3 * sizes.pixels, "the colour image");
    DeviceBuffer<float> d_alpha(sizes.pixels, "the alpha image");
    DeviceBuffer<float> d_depth(sizes.pixels, "the depth image");
    DeviceBuffer<std::int32_t> d_contrib(sizes.pixels, "the contributor image");
    check(cudaMemsetAsync(counters.get(), 0, 3 * sizeof(unsigned long long), stream), "clearing counters");
    check(cudaMemsetAsync(tile_starts.get(), 0, sizes.tiles * sizeof(std::uint32_t), stream), "clearing tile ranges");
    check(cudaMemsetAsync(tile_ends.get(), 0, sizes.tiles * sizeof(std::uint32_t), stream), "clearing tile ranges");

    // ---- 1. projection -----------------------------------------------------------------
    auto t0 = Clock::now();
    if (n > 0) {
        project_kernel<T><<<grid_blocks(n), kThreadsPerBlock, 0, stream>>>(
            g.view, sh_floats(g.view.sh_degree), view, records.get(), counts.get(), counters.get());
        check_launch("projection kernel");
    }
    sync(stream, "projection");
    stats.seconds_projection = seconds_since(t0);

    // ---- 2-5. binning -------------------------------------------------------------------
    t0 = Clock::now();
    std::uint64_t instances = 0;
    DeviceBuffer<std::uint64_t> keys, keys_alt;
    DeviceBuffer<std::uint32_t> values, values_alt;
    const std::uint32_t* sorted_values = nullptr;
    if (n > 0) {
        std::size_t scan_bytes = 0;
        check(cub::DeviceScan::InclusiveSum(nullptr, scan_bytes, counts.get(), ends.get(), n, stream),
              "sizing the scan");
        {
            DeviceBuffer<unsigned char> scratch(scan_bytes, "scan scratch space");
            check(cub::DeviceScan::InclusiveSum(scratch.get(), scan_bytes, counts.get(), ends.get(), n, stream),
                  "scanning tile counts");
            check(cudaMemcpyAsync(&instances, ends.get() + (n - 1), sizeof instances,
                                  cudaMemcpyDeviceToHost, stream),
                  "reading the instance count");
            sync(stream, "scan");
        }
        check_tile_instances(instances);
    }
    if (instances > 0) {
        // The largest allocations of the frame: say what the whole frame needs if they fail.
        const std::string what = "the sort of " + std::to_string(instances) +
                                 " tile instances (the frame needs " +
                                 std::to_string(sizes.bytes(instances, sizeof(SplatRecord<T>), !input.on_device) >> 20) +
                                 " MiB of device memory besides CUB's scratch space)";
        keys = DeviceBuffer<std::uint64_t>(instances, what.c_str());
        keys_alt = DeviceBuffer<std::uint64_t>(instances, what.c_str());
        values = DeviceBuffer<std::uint32_t>(instances, what.c_str());
        values_alt = DeviceBuffer<std::uint32_t>(instances, what.c_str());
        emit_kernel<T><<<grid_blocks(n), kThreadsPerBlock, 0, stream>>>(
            n, records.get(), counts.get(), ends.get(), plan.tiles_x, keys.get(), values.get());
        check_launch("key emission kernel");

        cub::DoubleBuffer<std::uint64_t> key_buf(keys.get(), keys_alt.get());
        cub::DoubleBuffer<std::uint32_t> value_buf(values.get(), values_alt.get());
        const int items = int(instances);
        std::size_t sort_bytes = 0;
        check(cub::DeviceRadixSort::SortPairs(nullptr, sort_bytes, key_buf, value_buf, items, 0,
                                              plan.sort_end_bit, stream),
              "sizing the sort");
        {
            DeviceBuffer<unsigned char> scratch(sort_bytes, "sort scratch space");
            check(cub::DeviceRadixSort::SortPairs(scratch.get(), sort_bytes, key_buf, value_buf, items,
                                                  0, plan.sort_end_bit, stream),
                  "sorting tile instances");
            ranges_kernel<<<grid_blocks(instances), kThreadsPerBlock, 0, stream>>>(
                key_buf.Current(), std::uint32_t(instances), tile_starts.get(), tile_ends.get());
            check_launch("tile range kernel");
            sync(stream, "sorting");
        }
        sorted_values = value_buf.Current();
    }
    stats.seconds_sorting = seconds_since(t0);

    // ---- 6. compositing ------------------------------------------------------------------
    t0 = Clock::now();
    const dim3 grid(unsigned(plan.tiles_x), unsigned(plan.tiles_y));
    const dim3 block(tiling::kTileSize, tiling::kTileSize);
    blend_kernel<T><<<grid, block, 0, stream>>>(sorted_values, tile_starts.get(), tile_ends.get(),
                                                records.get(), plan, blend, d_color.get(),
                                                d_alpha.get(), d_depth.get(), d_contrib.get(),
                                                counters.get() + 1);
    check_launch("compositing kernel");
    sync(stream, "compositing");
    const std::uint64_t px = sizes.pixels;
    check(cudaMemcpy(out.color, d_color.get(), 3 * px * sizeof(float), cudaMemcpyDeviceToHost), "downloading colour");
    check(cudaMemcpy(out.alpha, d_alpha.get(), px * sizeof(float), cudaMemcpyDeviceToHost), "downloading alpha");
    check(cudaMemcpy(out.depth, d_depth.get(), px * sizeof(float), cudaMemcpyDeviceToHost), "downloading depth");
    check(cudaMemcpy(out.contributors, d_contrib.get(), px * sizeof(std::int32_t), cudaMemcpyDeviceToHost),
          "downloading contributors");
    unsigned long long host_counters[3] = {0, 0, 0};
    check(cudaMemcpy(host_counters, counters.get(), sizeof host_counters, cudaMemcpyDeviceToHost),
          "downloading counters");
    stats.seconds_blending = seconds_since(t0);

    stats.visible = host_counters[0];
    stats.tile_instances = instances;
    stats.blends = host_counters[1];
    stats.contributions = host_counters[2];
    return stats;
}

float* upload_floats(const float* host, std::size_t n, const char* what) {
    require_device();
    void* p = nullptr;
    check(cudaMalloc(&p, (n > 0 ? n : 1) * sizeof(float)), what);
    if (n > 0) {
        const cudaError_t e = cudaMemcpy(p, host, n * sizeof(float), cudaMemcpyHostToDevice);
        if (e != cudaSuccess) cudaFree(p);
        check(e, what);
    }
    return static_cast<float*>(p);
}

void free_device(void* ptr) noexcept {
    if (ptr != nullptr) cudaFree(ptr);
}

template FrameStats render_frame<float>(const GaussianArrays&, const ViewParams<float>&,
                                        const BlendParams<float>&, const FramePlan&, const FrameOutput&);
template FrameStats render_frame<double>(const GaussianArrays&, const ViewParams<double>&,
                                         const BlendParams<double>&, const FramePlan&, const FrameOutput&);

}  // namespace avsplat::gpu
