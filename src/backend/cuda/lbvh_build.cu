// LBVH on the device (Karras 2012, "Maximizing Parallelism in the
// Construction of BVHs, Octrees, and k-d Trees"), building rf::build_lbvh's
// tree:
//  1. bounds:  one thread per triangle writes its box (the CPU's min/max
//     order) and the block-wise union of the box centres; one block unions
//     the block results into the centroid bounds.
//  2. morton:  30- or 63-bit codes of the box centres with the CPU's
//     MortonQuantizer (morton_code.h), built per thread from the bounds, so
//     the codes are bit-identical to morton_tree.cpp's.
//  3. sort:    cub::DeviceRadixSort::SortPairs of (code, triangle); stable,
//     so equal codes keep triangle order, as the CPU's radix sort does.
//  4. inner:   one thread per inner node, karras::build_inner, parent links.
//  5. boxes:   one thread per leaf walks up; an atomic counter per inner node
//     lets only the second arrival go on (karras::propagate_boxes_from_leaf).
//  6. The order and the child references go back to the host, which decides
//     the SAH leaf collapse and writes the canonical BVH (emit_karras_tree,
//     the CPU LBVH's own refit and emitter), so the BVH is build_lbvh's.
// Stages are timed with CUDA events around their kernels only; buffers are
// allocated and freed between stages so the peak holds only what one stage
// needs.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cub/device/device_radix_sort.cuh>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/build/karras_tree.h"
#include "accel/bvh/build/lbvh_emit.h"
#include "accel/bvh/build/morton_code.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/lbvh_build.h"
#include "rayforge/backend/cuda.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

constexpr int kBlockSize = 256;
constexpr int kWarps = kBlockSize / 32;
constexpr uint32_t kMaxBoundsBlocks = 1024;  // block results the second reduction pass unions

uint32_t blocks_for(uint64_t threads) { return static_cast<uint32_t>((threads + kBlockSize - 1) / kBlockSize); }

// std::min / std::max exactly (b < a ? b : a; a < b ? b : a), in the
// CPU's nesting, so boxes are bit-identical to morton_tree.cpp's.
__device__ __forceinline__ float std_min(float a, float b) { return b < a ? b : a; }
__device__ __forceinline__ float std_max(float a, float b) { return a < b ? b : a; }

__device__ __forceinline__ Box3f triangle_box(const Triangle& t) {
    Box3f b;
    b.lo = Vec3f(std_min(t.v0.x, std_min(t.v1.x, t.v2.x)), std_min(t.v0.y, std_min(t.v1.y, t.v2.y)),
                 std_min(t.v0.z, std_min(t.v1.z, t.v2.z)));
    b.hi = Vec3f(std_max(t.v0.x, std_max(t.v1.x, t.v2.x)), std_max(t.v0.y, std_max(t.v1.y, t.v2.y)),
                 std_max(t.v0.z, std_max(t.v1.z, t.v2.z)));
    return b;
}
__device__ __forceinline__ Vec3f box_center(const Box3f& b) { return (b.lo + b.hi) * 0.5f; }

// Union over the block's threads (warp shuffles, then the first warp over
// the warps' results); the result is valid in thread 0.
__device__ Box3f block_union(Box3f box) {
    __shared__ float warp_boxes[kWarps][6];
    for (int offset = 16; offset > 0; offset >>= 1) {
        Box3f other;
        other.lo = Vec3f(__shfl_down_sync(0xffffffffu, box.lo.x, offset), __shfl_down_sync(0xffffffffu, box.lo.y, offset),
                         __shfl_down_sync(0xffffffffu, box.lo.z, offset));
        other.hi = Vec3f(__shfl_down_sync(0xffffffffu, box.hi.x, offset), __shfl_down_sync(0xffffffffu, box.hi.y, offset),
                         __shfl_down_sync(0xffffffffu, box.hi.z, offset));
        box = karras::box_union(box, other);
    }
    const int lane = threadIdx.x % 32, warp = threadIdx.x / 32;
    if (lane == 0) {
        warp_boxes[warp][0] = box.lo.x, warp_boxes[warp][1] = box.lo.y, warp_boxes[warp][2] = box.lo.z;
        warp_boxes[warp][3] = box.hi.x, warp_boxes[warp][4] = box.hi.y, warp_boxes[warp][5] = box.hi.z;
    }
    __syncthreads();
    if (warp == 0) {
        box = Box3f{};
        if (lane < kWarps) {
            box.lo = Vec3f(warp_boxes[lane][0], warp_boxes[lane][1], warp_boxes[lane][2]);
            box.hi = Vec3f(warp_boxes[lane][3], warp_boxes[lane][4], warp_boxes[lane][5]);
        }
        for (int offset = kWarps / 2; offset > 0; offset >>= 1) {
            Box3f other;
            other.lo = Vec3f(__shfl_down_sync(0xffffffffu, box.lo.x, offset),
                             __shfl_down_sync(0xffffffffu, box.lo.y, offset),
                             __shfl_down_sync(0xffffffffu, box.lo.z, offset));
            other.hi = Vec3f(__shfl_down_sync(0xffffffffu, box.hi.x, offset),
                             __shfl_down_sync(0xffffffffu, box.hi.y, offset),
                             __shfl_down_sync(0xffffffffu, box.hi.z, offset));
            box = karras::box_union(box, other);
        }
    }
    return box;
}

// Stage 1a: triangle boxes and each block's union of box centres.
__global__ void triangle_boxes_kernel(const Triangle* triangles, uint32_t n, Box3f* boxes, Box3f* block_bounds) {
    Box3f centres;
    for (uint32_t i = blockIdx.x * kBlockSize + threadIdx.x; i < n; i += gridDim.x * kBlockSize) {
        const Box3f box = triangle_box(triangles[i]);
        boxes[i] = box;
        const Vec3f c = box_center(box);
        centres = karras::box_union(centres, Box3f{c, c});
    }
    centres = block_union(centres);
    if (threadIdx.x == 0) block_bounds[blockIdx.x] = centres;
}

// Stage 1b: one block unions the block results.
__global__ void union_kernel(const Box3f* block_bounds, uint32_t count, Box3f* bounds) {
    Box3f acc;
    for (uint32_t i = threadIdx.x; i < count; i += kBlockSize) acc = karras::box_union(acc, block_bounds[i]);
    acc = block_union(acc);
    if (threadIdx.x == 0) *bounds = acc;
}

// Stage 2: codes of the box centres and the identity order.
template <class Key>
__global__ void morton_kernel(const Box3f* boxes, uint32_t n, const Box3f* bounds, Key* keys, uint32_t* order) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    const MortonQuantizer quantizer(*bounds, sizeof(Key) == 4 ? 10 : 21);
    const Vec3f c = box_center(boxes[i]);
    if constexpr (sizeof(Key) == 4) {
        keys[i] = quantizer.code30(c);
    } else {
        keys[i] = quantizer.code63(c);
    }
    order[i] = i;
}

// Stage 4: one thread per inner node.
template <class Key>
__global__ void inner_nodes_kernel(const Key* keys, uint32_t n, uint32_t* children, uint32_t* inner_parent,
                                   uint32_t* leaf_parent) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i + 1 >= n) return;
    karras::build_inner(keys, n, i, children + 2 * size_t{i}, inner_parent, leaf_parent);
}

// Stage 5: one thread per leaf.
__global__ void boxes_kernel(karras::BoxPassView tree, uint32_t n) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    karras::propagate_boxes_from_leaf<karras::AtomicArrival>(tree, i);
}

// Sum of the live device buffers, and its maximum.
class MemoryMeter {
public:
    template <class T>
    void allocate(DeviceBuffer<T>& buffer, size_t count) {
        release(buffer);
        buffer.allocate(count);
        live_ += buffer.bytes();
        if (live_ > peak_) peak_ = live_;
    }
    template <class T>
    void release(DeviceBuffer<T>& buffer) {
        live_ -= buffer.bytes();
        buffer.release();
    }
    [[nodiscard]] size_t peak() const { return peak_; }

private:
    size_t live_ = 0, peak_ = 0;
};

// Two events around one stage's device work.
class StageTimer {
public:
    StageTimer() {
        RF_CUDA_CHECK(cudaEventCreate(&start_));
        const cudaError_t status = cudaEventCreate(&stop_);
        if (status != cudaSuccess) {
            cudaEventDestroy(start_);
            throw_cuda_error(status, "cudaEventCreate(&stop_)", __FILE__, __LINE__);
        }
    }
    ~StageTimer() {
        cudaEventDestroy(start_);
        cudaEventDestroy(stop_);
    }
    StageTimer(const StageTimer&) = delete;
    StageTimer& operator=(const StageTimer&) = delete;

    void start() { RF_CUDA_CHECK(cudaEventRecord(start_)); }
    // Waits for the stage (launch errors surface here) and returns its milliseconds.
    double stop() {
        RF_CUDA_CHECK(cudaGetLastError());
        RF_CUDA_CHECK(cudaEventRecord(stop_));
        RF_CUDA_CHECK(cudaEventSynchronize(stop_));
        float ms = 0.0f;
        RF_CUDA_CHECK(cudaEventElapsedTime(&ms, start_, stop_));
        return ms;
    }

private:
    cudaEvent_t start_ = nullptr, stop_ = nullptr;
};

template <class T>
std::vector<T> download_all(const DeviceBuffer<T>& buffer, size_t count) {
    std::vector<T> host(count);
    buffer.download(host);
    return host;
}

// The device pipeline for n >= 2 triangles. `raw` (when not null) receives
// every array of the tree; otherwise only the order and the children come back.
template <class Key>
void build_on_device(std::span<const Triangle> triangles, DeviceBuildStages& stages, DeviceKarrasTree& out,
                     bool raw) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    MemoryMeter meter;
    StageTimer timer;

    DeviceBuffer<Triangle> device_triangles("LBVH: triangles");
    meter.allocate(device_triangles, n);
    timer.start();
    device_triangles.upload(triangles);
    stages.upload_ms = timer.stop();

    // 1. Triangle boxes and the centroid bounds.
    DeviceBuffer<Box3f> boxes("LBVH: triangle boxes"), block_bounds("LBVH: block bounds"), bounds("LBVH: bounds");
    const uint32_t bounds_blocks = std::min<uint32_t>(blocks_for(n), kMaxBoundsBlocks);
    meter.allocate(boxes, n);
    meter.allocate(block_bounds, bounds_blocks);
    meter.allocate(bounds, 1);
    timer.start();
    triangle_boxes_kernel<<<bounds_blocks, kBlockSize>>>(device_triangles.data(), n, boxes.data(), block_bounds.data());
    union_kernel<<<1, kBlockSize>>>(block_bounds.data(), bounds_blocks, bounds.data());
    stages.bounds_ms = timer.stop();
    meter.release(device_triangles);
    meter.release(block_bounds);

    // 2. Morton codes, in the first halves of the sort's double buffers.
    DeviceBuffer<Key> keys[2] = {DeviceBuffer<Key>("LBVH: Morton codes"), DeviceBuffer<Key>("LBVH: sorted codes")};
    DeviceBuffer<uint32_t> values[2] = {DeviceBuffer<uint32_t>("LBVH: triangle order"),
                                        DeviceBuffer<uint32_t>("LBVH: sorted order")};
    for (int b = 0; b < 2; ++b) {
        meter.allocate(keys[b], n);
        meter.allocate(values[b], n);
    }
    timer.start();
    morton_kernel<Key><<<blocks_for(n), kBlockSize>>>(boxes.data(), n, bounds.data(), keys[0].data(), values[0].data());
    stages.morton_ms = timer.stop();

    // 3. Stable radix sort of (code, triangle) over the code bits.
    const int key_bits = sizeof(Key) == 4 ? 30 : 63;
    cub::DoubleBuffer<Key> key_buffers(keys[0].data(), keys[1].data());
    cub::DoubleBuffer<uint32_t> value_buffers(values[0].data(), values[1].data());
    size_t temp_bytes = 0;
    RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, key_buffers, value_buffers, n, 0, key_bits));
    DeviceBuffer<uint8_t> temp("LBVH: radix sort temporary storage");
    meter.allocate(temp, temp_bytes > 0 ? temp_bytes : 1);  // a null buffer would make CUB only query
    timer.start();
    RF_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(temp.data(), temp_bytes, key_buffers, value_buffers, n, 0, key_bits));
    stages.sort_ms = timer.stop();
    meter.release(temp);
    const int sorted = key_buffers.Current() == keys[0].data() ? 0 : 1;
    meter.release(keys[1 - sorted]);
    meter.release(values[1 - sorted]);
    const DeviceBuffer<Key>& sorted_keys = keys[sorted];
    const DeviceBuffer<uint32_t>& order = values[sorted];

    // 4. Inner nodes and parent links.
    DeviceBuffer<uint32_t> children("LBVH: child references"), inner_parent("LBVH: inner node parents"),
        leaf_parent("LBVH: leaf parents");
    meter.allocate(children, 2 * size_t{n - 1});
    meter.allocate(inner_parent, n - 1);
    meter.allocate(leaf_parent, n);
    timer.start();
    inner_nodes_kernel<Key><<<blocks_for(n - 1), kBlockSize>>>(sorted_keys.data(), n, children.data(),
                                                               inner_parent.data(), leaf_parent.data());
    stages.inner_nodes_ms = timer.stop();
    meter.release(keys[sorted]);

    // 5. Bottom-up boxes.
    DeviceBuffer<Box3f> inner_boxes("LBVH: inner node boxes");
    DeviceBuffer<uint32_t> arrivals("LBVH: arrival counters");
    meter.allocate(inner_boxes, n - 1);
    meter.allocate(arrivals, n - 1);
    const karras::BoxPassView view{children.data(), inner_parent.data(), leaf_parent.data(), boxes.data(),
                                   order.data(),    inner_boxes.data(),  arrivals.data()};
    timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    boxes_kernel<<<blocks_for(n), kBlockSize>>>(view, n);
    stages.boxes_ms = timer.stop();
    stages.peak_device_bytes = meter.peak();

    // 6. The tree back to the host.
    timer.start();
    out.order = download_all(order, n);
    out.children = download_all(children, 2 * size_t{n - 1});
    if (raw) {
        out.inner_parent = download_all(inner_parent, n - 1);
        out.leaf_parent = download_all(leaf_parent, n);
        out.arrivals = download_all(arrivals, n - 1);
        out.inner_boxes = download_all(inner_boxes, n - 1);
        out.triangle_boxes = download_all(boxes, n);
    }
    stages.download_ms = timer.stop();
}

void check_input(std::span<const Triangle> triangles, int morton_bits) {
    if (morton_bits != 30 && morton_bits != 63) {
        throw Error("LBVH: Morton code bits must be 30 or 63, got " + std::to_string(morton_bits));
    }
    if (triangles.size() >= karras::kLeafRef) throw Error("Morton BVH build: more than 2^31-1 triangles");
}

void build_raw(std::span<const Triangle> triangles, int morton_bits, DeviceBuildStages& stages, int device,
               DeviceKarrasTree& out, bool raw) {
    check_input(triangles, morton_bits);
    const size_t n = triangles.size();
    if (n < 2) {  // no inner nodes: nothing for the device to do
        out.order.assign(n, 0u);
        return;
    }
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    if (morton_bits == 30) {
        build_on_device<uint32_t>(triangles, stages, out, raw);
    } else {
        build_on_device<uint64_t>(triangles, stages, out, raw);
    }
}

}  // namespace

DeviceKarrasTree build_karras_tree_on_device(std::span<const Triangle> triangles, int morton_bits,
                                             DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceKarrasTree tree;
    build_raw(triangles, morton_bits, stages ? *stages : local, device, tree, true);
    return tree;
}

Bvh build_lbvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options, int morton_bits,
                         DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    DeviceKarrasTree tree;
    build_raw(triangles, morton_bits, s, device, tree, false);
    const auto start = std::chrono::steady_clock::now();
    Bvh bvh = emit_karras_tree(triangles, options, std::move(tree.order), tree.children);
    s.emit_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return bvh;
}

}  // namespace rf::cuda
