// HLBVH2 on the device (Garanzha, Pantaleoni and McAllister, HPG 2011;
// Garanzha 2014, dissertation ch. 5, "BVH construction with binary search
// and work queues"), building rf::build_hlbvh2's tree:
//  1. boxes, bounds, 30-bit Morton codes and ONE stable radix sort
//     (morton_sort.cu, shared with the LBVH).
//  2. clusters: a flag per sorted position where the top 15 bits change,
//     cub::DeviceSelect::Flagged of the positions (the cluster starts), then
//     one thread per cluster writes its level-0 task and 15-bit prefix.
//  3. bottom levels by work queues, one launch per level: each warp takes 32
//     tasks with one atomicAdd on the input queue's head (lane 0, broadcast
//     by shuffle); each thread splits its task with the shared HD step
//     (hlbvh2_bottom_steps.h process_task: binary search for the first 1 of the
//     highest differing bit; the node is written at index mid - 1, as the CPU
//     numbers it, so the trees are the CPU's by construction); inner children
//     are enqueued at a warp-local prefix sum (two ballots + popc) after one
//     atomicAdd per warp on the output queue's tail. The queues ping-pong;
//     no global scan. Each level's node indices are recorded (kNoNode for
//     leaves) for the box pass.
//  4. boxes bottom-up per level, deepest first, one launch per level, one
//     thread per recorded node (node_box), then the cluster boxes.
//  5. the top level over the clusters by task queues (hlbvh2_top_level.cu:
//     the grid SAH of ch. 4 with the top grid only, 8 lanes per task, the
//     CPU's tree by construction), then the top nodes' boxes bottom-up.
//  6. emission on the device (raw_tree_emit.cu): box, count, SAH cost and
//     leaf collapse per node bottom-up, the canonical layout, and the BVH
//     back to the host. Slots no split used are marked (references set to
//     kNoChild before step 3). A tree deeper than kBvhMaxDepth, or one leaf,
//     comes back raw (order, references, clusters, top level) and the host
//     checks, refits and emits it (emit_hlbvh2_forest). Either way the BVH
//     is build_hlbvh2's.
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cub/device/device_select.cuh>
#include <string>
#include <thrust/iterator/counting_iterator.h>
#include <utility>
#include <vector>

#include "accel/bvh/builders/hlbvh2_emit.h"
#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/raw_tree_emit.h"
#include "backend/cuda/hlbvh2_build.h"
#include "backend/cuda/hlbvh2_top_level.h"
#include "backend/cuda/morton_sort.h"
#include "backend/backends.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

using hlbvh2::Task;

constexpr int kBlockSize = 256;  // a multiple of 32: every warp is full, so full-mask ballots are valid
constexpr uint32_t kWarp = 32;
constexpr uint32_t kFullMask = 0xffffffffu;
constexpr uint32_t kMaxQueueBlocks = 4096;  // warps loop over the queue beyond this

uint32_t blocks_for(uint64_t threads) { return static_cast<uint32_t>((threads + kBlockSize - 1) / kBlockSize); }

// Stage 2a: 1 where a cluster starts (the top 15 bits change).
__global__ void cluster_flags_kernel(const uint32_t* keys, uint32_t n, uint8_t* flags) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    flags[i] = i == 0 || (keys[i] >> hlbvh2::kClusterShift) != (keys[i - 1] >> hlbvh2::kClusterShift);
}

// Stage 2b: one thread per cluster: its level-0 task (slot: its root) and prefix.
__global__ void level0_tasks_kernel(const uint32_t* keys, uint32_t n, const uint32_t* cluster_begin, uint32_t clusters,
                                    Task* tasks, uint32_t* prefix) {
    const uint32_t c = blockIdx.x * kBlockSize + threadIdx.x;
    if (c >= clusters) return;
    const uint32_t first = cluster_begin[c];
    const uint32_t end = c + 1 < clusters ? cluster_begin[c + 1] : n;
    tasks[c] = Task{first, end, 2 * (n - 1) + c};
    prefix[c] = keys[first] >> hlbvh2::kClusterShift;
}

// Stage 3: one level of the bottom trees. counters[0]: the input head,
// counters[1]: the output tail; both zero at launch.
__global__ void bottom_level_kernel(const uint32_t* keys, const Task* input, uint32_t count, Task* output,
                                    uint32_t* counters, uint32_t leaf_size, uint32_t* refs, uint8_t* leaf_runs,
                                    uint32_t* level_nodes) {
    const int lane = static_cast<int>(threadIdx.x % kWarp);
    for (;;) {
        uint32_t base = 0;
        if (lane == 0) base = atomicAdd(&counters[0], kWarp);  // one dequeue per warp
        base = __shfl_sync(kFullMask, base, 0);
        if (base >= count) return;  // uniform over the warp
        const uint32_t at = base + static_cast<uint32_t>(lane);
        Task children[2];
        uint32_t inner = 0;
        if (at < count) {
            uint32_t node = hlbvh2::kNoNode;
            inner = hlbvh2::process_task(keys, input[at], leaf_size, refs, leaf_runs, children, &node);
            level_nodes[at] = node;
        }
        const uint32_t one_or_more = __ballot_sync(kFullMask, inner >= 1), two = __ballot_sync(kFullMask, inner == 2);
        const uint32_t total = hlbvh2::enqueue_total(one_or_more, two);
        uint32_t out_base = 0;
        if (lane == 0 && total != 0) out_base = atomicAdd(&counters[1], total);  // one enqueue per warp
        out_base = __shfl_sync(kFullMask, out_base, 0);
        const uint32_t offset = out_base + hlbvh2::enqueue_offset(one_or_more, two, lane);
        for (uint32_t k = 0; k < inner; ++k) output[offset + k] = children[k];
    }
}

// Stage 4a: one level's boxes; the deeper levels are final.
__global__ void level_boxes_kernel(hlbvh2::BoxView view, const uint32_t* level_nodes, uint32_t count) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= count) return;
    const uint32_t node = level_nodes[i];
    if (node != hlbvh2::kNoNode) hlbvh2::node_box(view, node);
}

// Stage 4b: the clusters' boxes (a root may be a leaf).
__global__ void cluster_boxes_kernel(hlbvh2::BoxView view, const uint32_t* roots, uint32_t clusters, Box3f* boxes) {
    const uint32_t c = blockIdx.x * kBlockSize + threadIdx.x;
    if (c >= clusters) return;
    boxes[c] = hlbvh2::reference_box(view, roots[c]);
}

uint32_t download_value(const uint32_t* device_value) {
    uint32_t value = 0;
    RF_CUDA_CHECK(cudaMemcpy(&value, device_value, sizeof value, cudaMemcpyDeviceToHost));
    return value;
}

// The device pipeline for n >= 2 triangles. `raw`: the raw forest comes
// back whole. Otherwise, with `config`, the device emits the BVH into `bvh`
// and returns true; false when it could not (too deep, or one leaf), and
// then the forest came back in `out`.
bool build_forest(std::span<const Triangle> triangles, uint32_t leaf_size, DeviceBuildStages& stages,
                  DeviceHlbvh2Forest& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    MemoryMeter meter;
    EventTimer timer;

    // 1. Boxes, bounds, codes, the sort.
    DeviceMortonOrder<uint32_t> sorted;
    sort_triangles_by_morton_codes(triangles, "HLBVH2", stages, meter, timer, sorted);

    // 2. Clusters.
    DeviceBuffer<uint8_t> flags("HLBVH2: cluster flags");
    DeviceBuffer<uint32_t> cluster_begin("HLBVH2: cluster starts"), selected("HLBVH2: cluster count");
    meter.allocate(flags, n);
    meter.allocate(cluster_begin, n);  // at most one cluster per triangle
    meter.allocate(selected, 1);
    const thrust::counting_iterator<uint32_t> positions(0u);
    size_t temp_bytes = 0;
    RF_CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, temp_bytes, positions, flags.data(), cluster_begin.data(),
                                             selected.data(), n));
    DeviceBuffer<uint8_t> temp("HLBVH2: cluster compaction temporary storage");
    meter.allocate(temp, temp_bytes > 0 ? temp_bytes : 1);
    timer.start();
    cluster_flags_kernel<<<blocks_for(n), kBlockSize>>>(sorted.keys.data(), n, flags.data());
    RF_CUDA_CHECK(cub::DeviceSelect::Flagged(temp.data(), temp_bytes, positions, flags.data(), cluster_begin.data(),
                                             selected.data(), n));
    const uint32_t clusters = download_value(selected.data());
    stages.cluster_count = clusters;

    // Queues: level 0 holds the clusters; a later task has more than
    // leaf_size primitives, disjoint from the others', so a level holds at
    // most n / (leaf_size + 1).
    const uint32_t capacity = std::max(clusters, n / (leaf_size + 1) + 1);
    DeviceBuffer<Task> queue[2] = {DeviceBuffer<Task>("HLBVH2: task queue A"), DeviceBuffer<Task>("HLBVH2: task queue B")};
    DeviceBuffer<uint32_t> prefix("HLBVH2: cluster prefixes");
    meter.release(temp);
    meter.release(flags);
    meter.allocate(queue[0], capacity);
    meter.allocate(queue[1], capacity);
    meter.allocate(prefix, clusters);
    level0_tasks_kernel<<<blocks_for(clusters), kBlockSize>>>(sorted.keys.data(), n, cluster_begin.data(), clusters,
                                                              queue[0].data(), prefix.data());
    stages.clusters_ms = timer.stop_ms();

    // 3. Bottom levels.
    const size_t ref_count = 2 * (size_t{n} - 1) + clusters;
    DeviceBuffer<uint32_t> refs("HLBVH2: child references"), level_nodes("HLBVH2: level nodes"),
        counters("HLBVH2: queue counters");
    DeviceBuffer<uint8_t> leaf_runs("HLBVH2: leaf run sizes");
    meter.allocate(refs, ref_count);
    meter.allocate(level_nodes, size_t{clusters} + n - 1);  // every level-0 task, then distinct inner nodes
    meter.allocate(counters, 2);
    meter.allocate(leaf_runs, n);
    std::vector<uint32_t> level_sizes, level_base;
    uint32_t count = clusters, base = 0;
    int in = 0;
    timer.start();
    // Split positions no task reaches leave their node slot unused: marked for the emission.
    RF_CUDA_CHECK(cudaMemsetAsync(refs.data(), 0xff, refs.bytes()));
    while (count != 0) {
        if (base + size_t{count} > level_nodes.size()) throw Error("HLBVH2: bottom levels overran their node list");
        level_sizes.push_back(count);
        level_base.push_back(base);
        RF_CUDA_CHECK(cudaMemsetAsync(counters.data(), 0, counters.bytes()));
        const uint32_t blocks = std::min(blocks_for(count), kMaxQueueBlocks);
        bottom_level_kernel<<<blocks, kBlockSize>>>(sorted.keys.data(), queue[in].data(), count, queue[1 - in].data(),
                                                    counters.data(), leaf_size, refs.data(), leaf_runs.data(),
                                                    level_nodes.data() + base);
        RF_CUDA_CHECK(cudaGetLastError());
        base += count;
        count = download_value(counters.data() + 1);  // the next level's size (waits for this one)
        if (count > capacity) throw Error("HLBVH2: work queue overflow");
        in = 1 - in;
    }
    stages.bottom_ms = timer.stop_ms();
    stages.bottom_levels = static_cast<uint32_t>(level_sizes.size());
    meter.release(queue[0]);
    meter.release(queue[1]);
    meter.release(sorted.keys);

    // 4. Boxes, deepest level first, then the clusters'.
    DeviceBuffer<Box3f> inner_boxes("HLBVH2: inner node boxes"), cluster_boxes("HLBVH2: cluster boxes");
    meter.allocate(inner_boxes, n - 1);
    meter.allocate(cluster_boxes, clusters);
    const hlbvh2::BoxView view{refs.data(), leaf_runs.data(), sorted.order.data(), sorted.boxes.data(),
                               inner_boxes.data()};
    timer.start();
    for (size_t l = level_sizes.size(); l-- > 0;) {
        level_boxes_kernel<<<blocks_for(level_sizes[l]), kBlockSize>>>(view, level_nodes.data() + level_base[l],
                                                                       level_sizes[l]);
    }
    cluster_boxes_kernel<<<blocks_for(clusters), kBlockSize>>>(view, refs.data() + 2 * (size_t{n} - 1), clusters,
                                                               cluster_boxes.data());
    stages.boxes_ms = timer.stop_ms();
    meter.release(level_nodes);

    // 5. The top level over the clusters.
    DeviceTopLevel top;
    if (clusters >= 2) {
        DeviceTopLevelInput input;
        input.n = n;
        input.clusters = clusters;
        input.cluster_begin = cluster_begin.data();
        input.cluster_prefix = prefix.data();
        input.cluster_boxes = cluster_boxes.data();
        input.cluster_roots = refs.data() + 2 * (size_t{n} - 1);
        input.bottom = view;
        build_top_level_on_device(input, meter, timer, stages, top);
    }
    stages.peak_device_bytes = meter.peak();

    // 6. Emission on the device.
    if (!raw) {
        const uint32_t root = clusters >= 2 ? n - 1 : download_value(refs.data() + 2 * (size_t{n} - 1));
        if ((root & hlbvh2::kLeafRef) == 0) {
            meter.release(inner_boxes);
            meter.release(cluster_boxes);
            meter.release(counters);
            // The emission needs only the tree; the host's fallback gets the clusters from here.
            out.forest.cluster_begin = download_all(cluster_begin, clusters);
            out.forest.cluster_prefix = download_all(prefix, clusters);
            meter.release(cluster_begin);
            meter.release(prefix);
            DeviceRawTree tree;
            tree.children = refs.data();
            tree.high_children = clusters >= 2 ? top.top_refs.data() : nullptr;
            tree.high_base = n - 1;
            tree.node_slots = n - 1 + (clusters - 1);
            tree.root = root;
            tree.primitives = n;
            tree.boxes = sorted.boxes.data();
            tree.boxes_by_triangle = true;
            tree.order = sorted.order.data();
            tree.leaf_runs = leaf_runs.data();
            tree.sparse_slots = true;  // leaf runs leave most split positions without a node
            if (emit_raw_tree_on_device(tree, *config, "HLBVH2", meter, timer, stages, *bvh)) return true;
        }
    }

    // The raw tree for the host's refit and emission.
    timer.start();
    out.forest.order = download_all(sorted.order, n);
    out.forest.refs = download_all(refs, ref_count);
    if (out.forest.cluster_begin.empty()) {  // not already taken before the device emission
        out.forest.cluster_begin = download_all(cluster_begin, clusters);
        out.forest.cluster_prefix = download_all(prefix, clusters);
    }
    out.forest.cluster_begin.push_back(n);
    if (clusters >= 2) out.forest.top_refs = download_all(top.top_refs, 2 * (size_t{clusters} - 1));
    if (raw) {
        out.cluster_boxes = download_all(cluster_boxes, clusters);
        out.level_sizes = level_sizes;
        if (clusters >= 2) out.top_boxes = download_all(top.top_boxes, clusters - 1);
        out.top_level_sizes = top.level_sizes;
    }
    stages.download_ms += timer.stop_ms();
    return false;
}

// Returns true when the device emitted the BVH into *bvh (config and bvh given).
bool build_raw(std::span<const Triangle> triangles, uint32_t leaf_size, DeviceBuildStages& stages, int device,
               DeviceHlbvh2Forest& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr) {
    if (triangles.size() >= hlbvh2::kLeafRef / 2) throw Error("HLBVH2 device build: more than 2^30-1 triangles");
    if (leaf_size < 1 || leaf_size > 255) throw Error("HLBVH2 device build: leaf size must be in [1, 255]");
    if (triangles.size() < 2) return false;  // no inner nodes: the host does it
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    return build_forest(triangles, leaf_size, stages, out, raw, config, bvh);
}

}  // namespace

DeviceHlbvh2Forest build_hlbvh2_forest_on_device(std::span<const Triangle> triangles, uint32_t leaf_size,
                                                 DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceHlbvh2Forest forest;
    build_raw(triangles, leaf_size, stages ? *stages : local, device, forest, true);
    return forest;
}

Bvh build_hlbvh2_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                           DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    if (triangles.size() < 2) return build_hlbvh2(triangles, config);  // 0 or 1 triangles: nothing to queue
    DeviceHlbvh2Forest raw;
    Bvh bvh;
    if (build_raw(triangles, static_cast<uint32_t>(std::max(config.max_leaf_size, 1)), s, device, raw, false,
                  &config, &bvh)) {
        s.emitted_on_device = true;
        return bvh;
    }
    Hlbvh2Stages host;
    bvh = emit_hlbvh2_forest(triangles, config, std::move(raw.forest), &host);
    s.emit_ms = host.top_ms + host.emit_ms;  // the host checks and finalizes the device's top level
    return bvh;
}

}  // namespace rf::cuda
