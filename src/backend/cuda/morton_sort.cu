// The Morton front of the device builders (morton_sort.h): boxes, centroid
// bounds, Morton codes (the CPU's MortonQuantizer, morton_code.h) and one
// stable radix sort (CUB) of (code, triangle).
#include "backend/cuda/morton_sort.h"

#include <algorithm>
#include <cub/device/device_radix_sort.cuh>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/morton_code.h"
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

}  // namespace

template <class Key>
void sort_triangles_by_morton_codes(std::span<const Triangle> triangles, const std::string& label,
                                    DeviceBuildStages& stages, MemoryMeter& meter, EventTimer& timer,
                                    DeviceMortonOrder<Key>& out) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    DeviceBuffer<Triangle> device_triangles(label + ": triangles");
    meter.allocate(device_triangles, n);
    timer.start();
    device_triangles.upload(triangles);
    stages.upload_ms = timer.stop_ms();

    // 1. Triangle boxes and the centroid bounds.
    DeviceBuffer<Box3f>& boxes = out.boxes;
    boxes = DeviceBuffer<Box3f>(label + ": triangle boxes");
    DeviceBuffer<Box3f> block_bounds(label + ": block bounds"), bounds(label + ": bounds");
    const uint32_t bounds_blocks = std::min<uint32_t>(blocks_for(n), kMaxBoundsBlocks);
    meter.allocate(boxes, n);
    meter.allocate(block_bounds, bounds_blocks);
    meter.allocate(bounds, 1);
    timer.start();
    triangle_boxes_kernel<<<bounds_blocks, kBlockSize>>>(device_triangles.data(), n, boxes.data(), block_bounds.data());
    union_kernel<<<1, kBlockSize>>>(block_bounds.data(), bounds_blocks, bounds.data());
    stages.bounds_ms = timer.stop_ms();
    meter.release(device_triangles);
    meter.release(block_bounds);

    // 2. Morton codes, in the first halves of the sort's double buffers.
    DeviceBuffer<Key> keys[2] = {DeviceBuffer<Key>(label + ": Morton codes"), DeviceBuffer<Key>(label + ": sorted codes")};
    DeviceBuffer<uint32_t> values[2] = {DeviceBuffer<uint32_t>(label + ": triangle order"),
                                        DeviceBuffer<uint32_t>(label + ": sorted order")};
    for (int b = 0; b < 2; ++b) {
        meter.allocate(keys[b], n);
        meter.allocate(values[b], n);
    }
    timer.start();
    morton_kernel<Key><<<blocks_for(n), kBlockSize>>>(boxes.data(), n, bounds.data(), keys[0].data(), values[0].data());
    stages.morton_ms = timer.stop_ms();
    // `bounds` is freed on return without leaving the meter: the LBVH always
    // counted it live to the end, and its peak report stays as it was.

    // 3. Stable radix sort of (code, triangle) over the code bits.
    const int key_bits = sizeof(Key) == 4 ? 30 : 63;
    cub::DoubleBuffer<Key> key_buffers(keys[0].data(), keys[1].data());
    cub::DoubleBuffer<uint32_t> value_buffers(values[0].data(), values[1].data());
    size_t temp_bytes = 0;
    RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, key_buffers, value_buffers, n, 0, key_bits));
    DeviceBuffer<uint8_t> temp(label + ": radix sort temporary storage");
    meter.allocate(temp, temp_bytes > 0 ? temp_bytes : 1);  // a null buffer would make CUB only query
    timer.start();
    RF_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(temp.data(), temp_bytes, key_buffers, value_buffers, n, 0, key_bits));
    stages.sort_ms = timer.stop_ms();
    meter.release(temp);
    const int sorted = key_buffers.Current() == keys[0].data() ? 0 : 1;
    meter.release(keys[1 - sorted]);
    meter.release(values[1 - sorted]);
    out.keys = std::move(keys[sorted]);
    out.order = std::move(values[sorted]);
}

template void sort_triangles_by_morton_codes<uint32_t>(std::span<const Triangle>, const std::string&,
                                                       DeviceBuildStages&, MemoryMeter&, EventTimer&,
                                                       DeviceMortonOrder<uint32_t>&);
template void sort_triangles_by_morton_codes<uint64_t>(std::span<const Triangle>, const std::string&,
                                                       DeviceBuildStages&, MemoryMeter&, EventTimer&,
                                                       DeviceMortonOrder<uint64_t>&);

}  // namespace rf::cuda
