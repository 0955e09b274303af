// PLOC on the device (Meister and Bittner 2018, "Parallel Locally-Ordered
// Clustering for Bounding Volume Hierarchy Construction", IEEE TVCG),
// building rf::build_ploc's tree:
//  1. boxes, bounds, 63-bit Morton codes and ONE stable radix sort
//     (morton_sort.cu, shared with the LBVH and HLBVH2).
//  2. the initial clusters: one thread per sorted position writes its leaf
//     reference and gathers its triangle's box.
//  3. per iteration until one cluster is left (sec. 4), over the shared
//     per-cluster steps of accel/bvh/builders/ploc_steps.h:
//     a. nearest neighbours (sec. 4.2): one block per 256 clusters loads their
//        boxes and radius more on each side into shared memory; every pair
//        with an end in the block is evaluated once (window_pairs_from) and
//        offered to both ends by a 64-bit atomicMin on shared keys (area,
//        then the tie rule), so the result does not depend on the order of
//        the atomics. Radii too large for shared memory: one thread per
//        cluster searches global memory (nearest_neighbour).
//     b. one thread per cluster writes its (survivor, merge) flags, one more
//        a zero, and cub::DeviceScan::ExclusiveSum gives every cluster its
//        new position and node number (sec. 4.3: the order of the clusters,
//        as the CPU numbers them); the total (8 bytes) comes back to the
//        host: the next cluster count and the nodes made.
//     c. merge and compaction: one thread per cluster (compact_cluster):
//        the lower end of a mutual pair writes the new node (children, box)
//        and puts it at its position; other survivors move.
//  4. emission on the device (raw_tree_emit.cu): boxes, counts, SAH costs
//     and leaf collapse bottom-up, the canonical layout, and the BVH back to
//     the host; so the triangle boxes stay until then. A tree deeper than
//     kBvhMaxDepth comes back raw (order, children, nodes per iteration) and
//     the host refits and emits it (emit_ploc_tree, the CPU PLOC's own).
//     Either way the BVH is build_ploc's.
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter.
#include <cuda_runtime.h>

#include <chrono>
#include <cub/device/device_scan.cuh>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/ploc_emit.h"
#include "accel/bvh/builders/ploc_steps.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/raw_tree_emit.h"
#include "backend/cuda/morton_sort.h"
#include "backend/cuda/ploc_build.h"
#include "backend/backends.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

constexpr int kBlockSize = 256;             // threads per block, and clusters per neighbour window
constexpr uint32_t kMaxWindowRadius = 256;  // beyond this the window would not fit in shared memory

uint32_t blocks_for(uint64_t threads) { return static_cast<uint32_t>((threads + kBlockSize - 1) / kBlockSize); }

size_t window_shared_bytes(uint32_t radius) {
    return kBlockSize * sizeof(uint64_t) + (kBlockSize + 2 * size_t{radius}) * sizeof(Box3f);
}

// Stage 2: the sorted triangles as the first clusters.
__global__ void initial_clusters_kernel(const Box3f* triangle_boxes, const uint32_t* order, uint32_t n, uint32_t* refs,
                                        Box3f* boxes) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    refs[i] = ploc::kLeafRef | i;
    boxes[i] = triangle_boxes[order[i]];
}

// The minimum of the keys offered to a block's clusters, in shared memory.
struct SharedMinimum {
    uint64_t* keys;
    __device__ void operator()(uint32_t slot, uint64_t key) const {
        atomicMin(reinterpret_cast<unsigned long long*>(keys + slot), static_cast<unsigned long long>(key));
    }
};

// Stage 3a, the paper's shared-memory window: one block per kBlockSize
// clusters; dynamic shared memory holds their keys, then the window's boxes.
__global__ void __launch_bounds__(kBlockSize)
    window_neighbours_kernel(const Box3f* boxes, uint32_t count, uint32_t radius, uint32_t* neighbour) {
    extern __shared__ uint64_t shared_words[];
    uint64_t* keys = shared_words;
    Box3f* window_boxes = reinterpret_cast<Box3f*>(keys + kBlockSize);
    const ploc::Window w = ploc::block_window(blockIdx.x * kBlockSize, kBlockSize, count, radius);
    keys[threadIdx.x] = ploc::kNoNeighbour;
    for (uint32_t p = w.begin + threadIdx.x; p < w.end; p += kBlockSize) window_boxes[p - w.begin] = boxes[p];
    __syncthreads();
    SharedMinimum record{keys};
    for (uint32_t p = w.begin + threadIdx.x; p < w.block_end; p += kBlockSize) {
        ploc::window_pairs_from(window_boxes, w, radius, p, record);
    }
    __syncthreads();
    const uint32_t i = w.block_begin + threadIdx.x;
    if (i < w.block_end) neighbour[i] = ploc::neighbour_from_key(i, keys[threadIdx.x]);
}

// Stage 3a for large radii: one thread per cluster over global memory.
__global__ void neighbours_kernel(const Box3f* boxes, uint32_t count, uint32_t radius, uint32_t* neighbour) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= count) return;
    neighbour[i] = ploc::nearest_neighbour(boxes, count, radius, i);
}

// Stage 3b: count + 1 flags, the last zero, so the scan's last element is the total.
__global__ void flags_kernel(const uint32_t* neighbour, uint32_t count, uint64_t* flags) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i > count) return;
    flags[i] = i < count ? ploc::compaction_flags(neighbour, i) : 0;
}

// Stage 3c: one thread per cluster.
__global__ void compact_kernel(ploc::ClusterArrays arrays, const uint32_t* neighbour, const uint64_t* prefix,
                               uint32_t count, uint32_t next_node) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= count) return;
    ploc::compact_cluster(arrays, neighbour, i, prefix[i], next_node);
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The device pipeline for n >= 2 triangles. `raw`: the node boxes are kept
// and the raw tree comes back. Otherwise, with `config`, the device emits
// the BVH into `bvh` and returns true; false when the tree was too deep, and
// then the raw tree came back in `out`.
bool build_on_device(std::span<const Triangle> triangles, uint32_t radius, DeviceBuildStages& stages,
                     DevicePlocTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    MemoryMeter meter;
    EventTimer timer;

    // 1. Boxes, centroid bounds, 63-bit Morton codes, the sort (morton_sort.cu).
    DeviceMortonOrder<uint64_t> sorted;
    sort_triangles_by_morton_codes(triangles, "PLOC", stages, meter, timer, sorted);
    meter.release(sorted.keys);  // the order is all the clustering needs

    // 2. The first clusters; the per-triangle boxes are then spent.
    DeviceBuffer<uint32_t> refs[2] = {DeviceBuffer<uint32_t>("PLOC: cluster references"),
                                      DeviceBuffer<uint32_t>("PLOC: next cluster references")};
    DeviceBuffer<Box3f> boxes[2] = {DeviceBuffer<Box3f>("PLOC: cluster boxes"),
                                    DeviceBuffer<Box3f>("PLOC: next cluster boxes")};
    for (int b = 0; b < 2; ++b) {
        meter.allocate(refs[b], n);
        meter.allocate(boxes[b], n);
    }
    timer.start();
    initial_clusters_kernel<<<blocks_for(n), kBlockSize>>>(sorted.boxes.data(), sorted.order.data(), n,
                                                           refs[0].data(), boxes[0].data());
    stages.ploc_ms = timer.stop_ms();
    if (raw) meter.release(sorted.boxes);  // the device emission needs them

    // 3. The iterations.
    DeviceBuffer<uint32_t> neighbour("PLOC: nearest neighbours"), children("PLOC: child references");
    DeviceBuffer<uint64_t> flags("PLOC: compaction flags"), prefix("PLOC: compaction prefix sums");
    DeviceBuffer<Box3f> node_boxes("PLOC: node boxes");
    meter.allocate(neighbour, n);
    meter.allocate(children, 2 * size_t{n - 1});
    meter.allocate(flags, size_t{n} + 1);
    meter.allocate(prefix, size_t{n} + 1);
    if (raw) meter.allocate(node_boxes, n - 1);
    size_t temp_bytes = 0;
    RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, flags.data(), prefix.data(), n + 1));
    DeviceBuffer<uint8_t> temp("PLOC: scan temporary storage");
    meter.allocate(temp, temp_bytes > 0 ? temp_bytes : 1);

    const bool window = radius <= kMaxWindowRadius;
    const size_t shared_bytes = window_shared_bytes(radius);
    uint32_t count = n, next_node = 0;
    int current = 0;
    out.iteration_nodes.clear();
    timer.start();
    while (count > 1) {
        const DeviceBuffer<Box3f>& cluster_boxes = boxes[current];
        if (window) {
            window_neighbours_kernel<<<blocks_for(count), kBlockSize, shared_bytes>>>(cluster_boxes.data(), count,
                                                                                      radius, neighbour.data());
        } else {
            neighbours_kernel<<<blocks_for(count), kBlockSize>>>(cluster_boxes.data(), count, radius,
                                                                 neighbour.data());
        }
        flags_kernel<<<blocks_for(size_t{count} + 1), kBlockSize>>>(neighbour.data(), count, flags.data());
        RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp.data(), temp_bytes, flags.data(), prefix.data(), count + 1));
        const ploc::ClusterArrays arrays{refs[current].data(),     cluster_boxes.data(), refs[1 - current].data(),
                                         boxes[1 - current].data(), children.data(),
                                         raw ? node_boxes.data() : nullptr};
        compact_kernel<<<blocks_for(count), kBlockSize>>>(arrays, neighbour.data(), prefix.data(), count, next_node);
        RF_CUDA_CHECK(cudaGetLastError());
        uint64_t total = 0;
        RF_CUDA_CHECK(cudaMemcpy(&total, prefix.data() + count, sizeof total, cudaMemcpyDeviceToHost));
        const uint32_t survivors = static_cast<uint32_t>(total >> 32), merges = static_cast<uint32_t>(total);
        // The closest pair is always mutual; anything else is a device fault, not a reason to spin.
        if (merges == 0 || survivors != count - merges) {
            throw Error("PLOC on the device: iteration " + std::to_string(out.iteration_nodes.size()) + " kept " +
                        std::to_string(survivors) + " of " + std::to_string(count) + " clusters with " +
                        std::to_string(merges) + " merges");
        }
        out.iteration_nodes.push_back(merges);
        next_node += merges;
        count = survivors;
        current = 1 - current;
    }
    stages.ploc_ms += timer.stop_ms();
    stages.ploc_iterations = static_cast<uint32_t>(out.iteration_nodes.size());
    stages.peak_device_bytes = meter.peak();

    // 4. Emission on the device.
    if (!raw) {
        for (int b = 0; b < 2; ++b) {
            meter.release(refs[b]);
            meter.release(boxes[b]);
        }
        meter.release(neighbour);
        meter.release(flags);
        meter.release(prefix);
        meter.release(temp);
        DeviceRawTree tree;
        tree.children = children.data();
        tree.node_slots = n - 1;
        tree.root = n - 2;
        tree.primitives = n;
        tree.boxes = sorted.boxes.data();
        tree.boxes_by_triangle = true;
        tree.order = sorted.order.data();
        if (emit_raw_tree_on_device(tree, *config, "PLOC", meter, timer, stages, *bvh)) return true;
    }

    // The clustering back to the host.
    timer.start();
    out.order = download_all(sorted.order, n);
    out.children = download_all(children, 2 * size_t{n - 1});
    if (raw) out.node_boxes = download_all(node_boxes, n - 1);
    stages.download_ms += timer.stop_ms();
    return false;
}

// Returns true when the device emitted the BVH into *bvh (config and bvh given).
bool build_raw(std::span<const Triangle> triangles, int radius, DeviceBuildStages& stages, int device,
               DevicePlocTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr) {
    if (triangles.size() >= ploc::kLeafRef) throw Error("PLOC on the device: more than 2^31-1 triangles");
    const size_t n = triangles.size();
    if (n < 2) {  // no merges: nothing for the device to do
        out.order.assign(n, 0u);
        return false;
    }
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    return build_on_device(triangles, ploc::clamp_radius(radius), stages, out, raw, config, bvh);
}

}  // namespace

DevicePlocTree build_ploc_tree_on_device(std::span<const Triangle> triangles, int radius, DeviceBuildStages* stages,
                                         int device) {
    DeviceBuildStages local;
    DevicePlocTree tree;
    build_raw(triangles, radius, stages ? *stages : local, device, tree, true);
    return tree;
}

Bvh build_ploc_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                         const PlocOptions& ploc_options, DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    DevicePlocTree tree;
    Bvh bvh;
    if (build_raw(triangles, ploc_options.radius, s, device, tree, false, &config, &bvh)) {
        s.emitted_on_device = true;
        return bvh;
    }
    const auto start = std::chrono::steady_clock::now();
    bvh = emit_ploc_tree(triangles, config, std::move(tree.order), tree.children, tree.iteration_nodes);
    s.emit_ms = elapsed_ms(start);
    return bvh;
}

}  // namespace rf::cuda
