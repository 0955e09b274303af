// The Morton front of the device builders (morton_sort.h): boxes, centroid
// bounds, Morton codes (the CPU's MortonQuantizer, morton_code.h) and one
// stable radix sort (CUB) of (code, triangle).
#include "backend/cuda/morton_sort.h"

#include <cub/device/device_radix_sort.cuh>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/morton_code.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/launch.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

constexpr int kWarps = kBlockSize / 32;
constexpr uint32_t kMaxBoundsBlocks = 1024;  // block results the second reduction pass unions

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

// Stage 1: the triangles' boxes and the centroid bounds, into `out`; the
// uploaded triangles and the block results are freed on return.
template <class Key>
void bound_triangles(std::span<const Triangle> triangles, const std::string& label, BuildContext& build,
                     DeviceMortonOrder<Key>& out) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    DeviceBuffer<Triangle> device_triangles(build.meter, label + ": triangles", n);
    build.timer.start();
    device_triangles.upload(triangles);
    build.stages.upload_ms = build.timer.stop_ms();

    const uint32_t bounds_blocks = strided_blocks_for(n, kMaxBoundsBlocks);
    out.boxes = DeviceBuffer<Box3f>(build.meter, label + ": triangle boxes", n);
    DeviceBuffer<Box3f> block_bounds(build.meter, label + ": block bounds", bounds_blocks);
    out.bounds = DeviceBuffer<Box3f>(build.meter, label + ": bounds", 1);
    build.timer.start();
    launch_shaped(triangle_boxes_kernel, {bounds_blocks}, device_triangles.data(), n, out.boxes.data(),
                  block_bounds.data());
    launch_shaped(union_kernel, {1}, block_bounds.data(), bounds_blocks, out.bounds.data());
    build.stages.bounds_ms = build.timer.stop_ms();
}

// Stages 2-3: the codes, in the first halves of the sort's double buffers,
// and the stable radix sort of (code, triangle) over the code bits; the
// halves that did not end sorted are freed on return.
template <class Key>
void sort_by_codes(uint32_t n, const std::string& label, BuildContext& build, DeviceMortonOrder<Key>& out) {
    DeviceBuffer<Key> keys[2] = {DeviceBuffer<Key>(build.meter, label + ": Morton codes", n),
                                 DeviceBuffer<Key>(build.meter, label + ": sorted codes", n)};
    DeviceBuffer<uint32_t> values[2] = {DeviceBuffer<uint32_t>(build.meter, label + ": triangle order", n),
                                        DeviceBuffer<uint32_t>(build.meter, label + ": sorted order", n)};
    build.timer.start();
    launch(morton_kernel<Key>, n, out.boxes.data(), n, out.bounds.data(), keys[0].data(), values[0].data());
    build.stages.morton_ms = build.timer.stop_ms();

    const int key_bits = sizeof(Key) == 4 ? 30 : 63;
    cub::DoubleBuffer<Key> key_buffers(keys[0].data(), keys[1].data());
    cub::DoubleBuffer<uint32_t> value_buffers(values[0].data(), values[1].data());
    const auto sort = [&](void* temp, size_t& bytes) {
        return cub::DeviceRadixSort::SortPairs(temp, bytes, key_buffers, value_buffers, n, 0, key_bits);
    };
    {
        DeviceBuffer<uint8_t> scratch(build.meter, label + ": radix sort temporary storage");
        cub_reserve(scratch, sort);  // allocated outside the timed sort
        build.timer.start();
        cub_run(scratch, sort);
        build.stages.sort_ms = build.timer.stop_ms();
    }
    const int sorted = key_buffers.Current() == keys[0].data() ? 0 : 1;
    out.keys = std::move(keys[sorted]);
    out.order = std::move(values[sorted]);
}

}  // namespace

template <class Key>
DeviceMortonOrder<Key> sort_triangles_by_morton_codes(std::span<const Triangle> triangles, const std::string& label,
                                                      BuildContext& build) {
    DeviceMortonOrder<Key> out;
    bound_triangles(triangles, label, build, out);
    sort_by_codes(static_cast<uint32_t>(triangles.size()), label, build, out);
    return out;
}

template DeviceMortonOrder<uint32_t> sort_triangles_by_morton_codes<uint32_t>(std::span<const Triangle>,
                                                                              const std::string&, BuildContext&);
template DeviceMortonOrder<uint64_t> sort_triangles_by_morton_codes<uint64_t>(std::span<const Triangle>,
                                                                              const std::string&, BuildContext&);

}  // namespace rf::cuda
