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
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter
// and live in the scope of the stages that use them.
#include <cuda_runtime.h>

#include <chrono>
#include <cub/device/device_scan.cuh>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/ploc_emit.h"
#include "accel/bvh/builders/ploc_steps.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/morton_sort.h"
#include "backend/cuda/ploc_build.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

// kBlockSize (launch.h) is also the clusters per neighbour window.
constexpr uint32_t kMaxWindowRadius = 256;  // beyond this the window would not fit in shared memory

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

// The clusters, ping-ponged by the iterations: references and boxes.
struct ClusterBuffers {
    DeviceBuffer<uint32_t> refs[2];
    DeviceBuffer<Box3f> boxes[2];
};

// What the clustering leaves: the nodes, in creation order.
struct PlocNodes {
    DeviceBuffer<uint32_t> children;  // 2 (n - 1)
    DeviceBuffer<Box3f> boxes;        // raw trees only: n - 1, as the merges wrote them
};

// Stage 2: the sorted triangles as the first clusters.
ClusterBuffers first_clusters(const DeviceMortonOrder<uint64_t>& sorted, uint32_t n, BuildContext& build) {
    ClusterBuffers clusters{{DeviceBuffer<uint32_t>(build.meter, "PLOC: cluster references", n),
                             DeviceBuffer<uint32_t>(build.meter, "PLOC: next cluster references", n)},
                            {DeviceBuffer<Box3f>(build.meter, "PLOC: cluster boxes", n),
                             DeviceBuffer<Box3f>(build.meter, "PLOC: next cluster boxes", n)}};
    build.timer.start();
    launch(initial_clusters_kernel, n, sorted.boxes.data(), sorted.order.data(), n, clusters.refs[0].data(),
           clusters.boxes[0].data());
    build.stages.ploc_ms = build.timer.stop_ms();
    return clusters;
}

// What an iteration works in, sized for the first (n clusters).
struct IterationArrays {
    DeviceBuffer<uint32_t> neighbour;
    DeviceBuffer<uint64_t> flags, prefix;  // count + 1: the last flag is zero, so the scan ends with the total
    DeviceBuffer<uint8_t> scratch;         // the scan's
};

// One iteration over `count` clusters in clusters[current] (3a-c): the
// merges, the survivors into the other buffers. Returns the total of the
// flags: (survivors << 32) | merges.
uint64_t merge_iteration(ClusterBuffers& clusters, int current, uint32_t count, uint32_t radius, uint32_t next_node,
                         IterationArrays& work, PlocNodes& nodes) {
    const Box3f* cluster_boxes = clusters.boxes[current].data();
    uint32_t* neighbour = work.neighbour.data();
    if (radius <= kMaxWindowRadius) {
        launch_shaped(window_neighbours_kernel, {blocks_for(count), kBlockSize, window_shared_bytes(radius)},
                      cluster_boxes, count, radius, neighbour);
    } else {
        launch(neighbours_kernel, count, cluster_boxes, count, radius, neighbour);
    }
    launch(flags_kernel, size_t{count} + 1, neighbour, count, work.flags.data());
    cub_run(work.scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::ExclusiveSum(temp, bytes, work.flags.data(), work.prefix.data(), count + 1);
    });
    const ploc::ClusterArrays arrays{clusters.refs[current].data(),     cluster_boxes,
                                     clusters.refs[1 - current].data(), clusters.boxes[1 - current].data(),
                                     nodes.children.data(),             nodes.boxes.data()};
    launch(compact_kernel, count, arrays, neighbour, work.prefix.data(), count, next_node);
    return download_value(work.prefix.data() + count);
}

// Stage 3: iterations until one cluster is left, timed as one; the nodes
// made per iteration into `iteration_nodes`. The iterations' arrays are
// freed on return.
void merge_until_one(ClusterBuffers& clusters, uint32_t n, uint32_t radius, PlocNodes& nodes, BuildContext& build,
                     std::vector<uint32_t>& iteration_nodes) {
    IterationArrays work{DeviceBuffer<uint32_t>(build.meter, "PLOC: nearest neighbours", n),
                         DeviceBuffer<uint64_t>(build.meter, "PLOC: compaction flags", size_t{n} + 1),
                         DeviceBuffer<uint64_t>(build.meter, "PLOC: compaction prefix sums", size_t{n} + 1),
                         DeviceBuffer<uint8_t>(build.meter, "PLOC: scan temporary storage")};
    cub_reserve(work.scratch, [&](void* temp, size_t& bytes) {  // the largest scan, allocated outside the timing
        return cub::DeviceScan::ExclusiveSum(temp, bytes, work.flags.data(), work.prefix.data(), n + 1);
    });
    uint32_t count = n, next_node = 0;
    int current = 0;
    iteration_nodes.clear();
    build.timer.start();
    while (count > 1) {
        const uint64_t total = merge_iteration(clusters, current, count, radius, next_node, work, nodes);
        const uint32_t survivors = static_cast<uint32_t>(total >> 32), merges = static_cast<uint32_t>(total);
        // The closest pair is always mutual; anything else is a device fault, not a reason to spin.
        if (merges == 0 || survivors != count - merges) {
            throw Error("PLOC on the device: iteration " + std::to_string(iteration_nodes.size()) + " kept " +
                        std::to_string(survivors) + " of " + std::to_string(count) + " clusters with " +
                        std::to_string(merges) + " merges");
        }
        iteration_nodes.push_back(merges);
        next_node += merges;
        count = survivors;
        current = 1 - current;
    }
    build.stages.ploc_ms += build.timer.stop_ms();
    build.stages.ploc_iterations = static_cast<uint32_t>(iteration_nodes.size());
    build.stages.peak_device_bytes = build.meter.peak();
}

// Stages 2-3: the clustering of the sorted triangles; the clusters are
// freed on return. Raw trees keep the node boxes instead of the triangle
// boxes, which only the device emission reads after the first clusters.
PlocNodes cluster(DeviceMortonOrder<uint64_t>& sorted, uint32_t n, uint32_t radius, bool raw, BuildContext& build,
                  std::vector<uint32_t>& iteration_nodes) {
    ClusterBuffers clusters = first_clusters(sorted, n, build);
    if (raw) sorted.boxes.release();
    PlocNodes nodes{DeviceBuffer<uint32_t>(build.meter, "PLOC: child references", 2 * size_t{n - 1}),
                    DeviceBuffer<Box3f>(build.meter, "PLOC: node boxes", raw ? n - 1 : 0)};
    merge_until_one(clusters, n, radius, nodes, build, iteration_nodes);
    return nodes;
}

// The device pipeline for n >= 2 triangles. `raw`: the node boxes are kept
// and the raw tree comes back. Otherwise, with `config`, the device emits
// the BVH into `bvh` and returns true; false when the tree was too deep, and
// then the raw tree came back in `out`.
bool build_on_device(std::span<const Triangle> triangles, uint32_t radius, DeviceBuildStages& stages,
                     DevicePlocTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    BuildContext build(stages);
    // 1. Boxes, centroid bounds, 63-bit Morton codes, the sort (morton_sort.cu).
    DeviceMortonOrder<uint64_t> sorted = sort_triangles_by_morton_codes<uint64_t>(triangles, "PLOC", build);
    sorted.keys.release();  // the order is all the clustering needs
    // 2-3. The clustering.
    const PlocNodes nodes = cluster(sorted, n, radius, raw, build, out.iteration_nodes);

    // 4. Emission on the device.
    if (!raw) {
        DeviceRawTree tree;
        tree.children = nodes.children.data();
        tree.node_slots = n - 1;
        tree.root = n - 2;
        tree.primitives = n;
        tree.boxes = sorted.boxes.data();
        tree.boxes_by_triangle = true;
        tree.order = sorted.order.data();
        if (emit_raw_tree_on_device(tree, *config, "PLOC", build, *bvh)) return true;
    }

    // The clustering back to the host.
    build.timer.start();
    out.order = download_all(sorted.order, n);
    out.children = download_all(nodes.children, 2 * size_t{n - 1});
    if (raw) out.node_boxes = download_all(nodes.boxes, n - 1);
    build.stages.download_ms += build.timer.stop_ms();
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
