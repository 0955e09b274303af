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
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter
// and live in the scope of the stages that use them.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cub/device/device_select.cuh>
#include <string>
#include <thrust/iterator/counting_iterator.h>
#include <utility>
#include <vector>

#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "accel/bvh/builders/hlbvh2_emit.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/hlbvh2_build.h"
#include "backend/cuda/hlbvh2_top_level.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/morton_sort.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

using hlbvh2::Task;

constexpr uint32_t kWarp = 32;  // kBlockSize (launch.h) is a multiple: full-mask ballots are valid
constexpr uint32_t kFullMask = 0xffffffffu;
constexpr uint32_t kMaxQueueBlocks = 4096;  // warps loop over the queue beyond this

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

// What lives to the end of a build: the sorted triangles, the bottom
// trees (references, leaf runs) and the top level.
struct ForestOnDevice {
    uint32_t n = 0, clusters = 0;
    DeviceMortonOrder<uint32_t> sorted;
    DeviceBuffer<uint32_t> refs;  // 2 (n - 1) split slots, then the cluster roots
    DeviceBuffer<uint8_t> leaf_runs;
    std::vector<uint32_t> level_sizes;  // bottom tasks per work-queue level
    DeviceTopLevel top;
    [[nodiscard]] size_t ref_count() const { return 2 * (size_t{n} - 1) + clusters; }
    [[nodiscard]] const uint32_t* cluster_roots() const { return refs.data() + 2 * (size_t{n} - 1); }
};

// The bottom levels' task queues, ping-ponged; level 0 (the clusters) in buffers[0].
struct TaskQueues {
    DeviceBuffer<Task> buffers[2];
    uint32_t capacity = 0;
};

// Runs of equal 15-bit prefixes of the sorted codes.
struct Clusters {
    DeviceBuffer<uint32_t> begin;   // first sorted position of each
    DeviceBuffer<uint32_t> prefix;  // 15-bit prefix of each
    TaskQueues queues;
};

// Stage 2a: flags where the prefix changes, compacted into the cluster
// starts (`begin`, room for n); the flags, the count and the scratch are
// freed on return. Starts the stage's timer; returns the cluster count.
uint32_t compact_cluster_starts(const ForestOnDevice& f, DeviceBuffer<uint32_t>& begin, BuildContext& build) {
    const uint32_t n = f.n;
    DeviceBuffer<uint8_t> flags(build.meter, "HLBVH2: cluster flags", n);
    DeviceBuffer<uint32_t> selected(build.meter, "HLBVH2: cluster count", 1);
    DeviceBuffer<uint8_t> scratch(build.meter, "HLBVH2: cluster compaction temporary storage");
    const thrust::counting_iterator<uint32_t> positions(0u);
    const auto select = [&](void* temp, size_t& bytes) {
        return cub::DeviceSelect::Flagged(temp, bytes, positions, flags.data(), begin.data(), selected.data(), n);
    };
    cub_reserve(scratch, select);
    build.timer.start();
    launch(cluster_flags_kernel, n, f.sorted.keys.data(), n, flags.data());
    cub_run(scratch, select);
    return download_value(selected.data());
}

// Stage 2, timed as clusters_ms: the clusters, their prefixes and the
// level-0 tasks in the first queue. A later task has more than leaf_size
// primitives, disjoint from the others', so a level holds at most
// n / (leaf_size + 1) tasks.
Clusters find_clusters(ForestOnDevice& f, uint32_t leaf_size, BuildContext& build) {
    Clusters found;
    found.begin = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: cluster starts", f.n);  // at most one per triangle
    f.clusters = compact_cluster_starts(f, found.begin, build);
    build.stages.cluster_count = f.clusters;
    TaskQueues& queues = found.queues;
    queues.capacity = std::max(f.clusters, f.n / (leaf_size + 1) + 1);
    queues.buffers[0] = DeviceBuffer<Task>(build.meter, "HLBVH2: task queue A", queues.capacity);
    queues.buffers[1] = DeviceBuffer<Task>(build.meter, "HLBVH2: task queue B", queues.capacity);
    found.prefix = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: cluster prefixes", f.clusters);
    launch(level0_tasks_kernel, f.clusters, f.sorted.keys.data(), f.n, found.begin.data(), f.clusters,
           queues.buffers[0].data(), found.prefix.data());
    build.stages.clusters_ms = build.timer.stop_ms();
    return found;
}

// Stage 3, timed as bottom_ms: the bottom levels, one launch per level,
// into f.refs and f.leaf_runs. Returns the levels' recorded nodes (every
// level-0 task, then distinct inner nodes; level_base: each level's first);
// the sorted codes and the queues are spent, freed on return.
DeviceBuffer<uint32_t> build_bottom_levels(ForestOnDevice& f, DeviceBuffer<uint32_t> sorted_keys, TaskQueues queues,
                                           uint32_t leaf_size, BuildContext& build,
                                           std::vector<uint32_t>& level_base) {
    f.refs = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: child references", f.ref_count());
    DeviceBuffer<uint32_t> level_nodes(build.meter, "HLBVH2: level nodes", size_t{f.clusters} + f.n - 1);
    DeviceBuffer<uint32_t> counters(build.meter, "HLBVH2: queue counters", 2);  // input head, output tail
    f.leaf_runs = DeviceBuffer<uint8_t>(build.meter, "HLBVH2: leaf run sizes", f.n);
    uint32_t count = f.clusters, base = 0;
    int in = 0;
    build.timer.start();
    // Split positions no task reaches leave their node slot unused: marked for the emission.
    RF_CUDA_CHECK(cudaMemsetAsync(f.refs.data(), 0xff, f.refs.bytes()));
    while (count != 0) {
        if (base + size_t{count} > level_nodes.size()) throw Error("HLBVH2: bottom levels overran their node list");
        f.level_sizes.push_back(count);
        level_base.push_back(base);
        RF_CUDA_CHECK(cudaMemsetAsync(counters.data(), 0, counters.bytes()));
        launch_shaped(bottom_level_kernel, {strided_blocks_for(count, kMaxQueueBlocks)}, sorted_keys.data(),
                      queues.buffers[in].data(), count, queues.buffers[1 - in].data(), counters.data(), leaf_size,
                      f.refs.data(), f.leaf_runs.data(), level_nodes.data() + base);
        base += count;
        count = download_value(counters.data() + 1);  // the next level's size (waits for this one)
        if (count > queues.capacity) throw Error("HLBVH2: work queue overflow");
        in = 1 - in;
    }
    build.stages.bottom_ms = build.timer.stop_ms();
    build.stages.bottom_levels = static_cast<uint32_t>(f.level_sizes.size());
    return level_nodes;
}

// The bottom trees' boxes.
struct ForestBoxes {
    DeviceBuffer<Box3f> inner;     // per inner node
    DeviceBuffer<Box3f> clusters;  // per cluster
    [[nodiscard]] hlbvh2::BoxView view(const ForestOnDevice& f) const {
        return {f.refs.data(), f.leaf_runs.data(), f.sorted.order.data(), f.sorted.boxes.data(), inner.data()};
    }
};

// Stage 4, timed as boxes_ms: boxes level by level, deepest first, then the
// clusters'; the recorded level nodes are spent, freed on return.
ForestBoxes box_bottom_levels(const ForestOnDevice& f, DeviceBuffer<uint32_t> level_nodes,
                              const std::vector<uint32_t>& level_base, BuildContext& build) {
    ForestBoxes boxes{DeviceBuffer<Box3f>(build.meter, "HLBVH2: inner node boxes", f.n - 1),
                      DeviceBuffer<Box3f>(build.meter, "HLBVH2: cluster boxes", f.clusters)};
    const hlbvh2::BoxView view = boxes.view(f);
    build.timer.start();
    for (size_t l = f.level_sizes.size(); l-- > 0;) {
        launch(level_boxes_kernel, f.level_sizes[l], view, level_nodes.data() + level_base[l], f.level_sizes[l]);
    }
    launch(cluster_boxes_kernel, f.clusters, view, f.cluster_roots(), f.clusters, boxes.clusters.data());
    build.stages.boxes_ms = build.timer.stop_ms();
    return boxes;
}

// Stage 5: the top level over the clusters (hlbvh2_top_level.cu).
DeviceTopLevel build_top_level(const ForestOnDevice& f, const Clusters& found, const ForestBoxes& boxes,
                               BuildContext& build) {
    DeviceTopLevelInput input;
    input.n = f.n;
    input.clusters = f.clusters;
    input.cluster_begin = found.begin.data();
    input.cluster_prefix = found.prefix.data();
    input.cluster_boxes = boxes.clusters.data();
    input.cluster_roots = f.cluster_roots();
    input.bottom = boxes.view(f);
    return build_top_level_on_device(input, build);
}

// Stage 6: the emission on the device, of the tree alone.
bool emit_on_device(const ForestOnDevice& f, uint32_t root, const BvhBuildConfig& config, BuildContext& build,
                    Bvh& bvh) {
    DeviceRawTree tree;
    tree.children = f.refs.data();
    tree.high_children = f.clusters >= 2 ? f.top.top_refs.data() : nullptr;
    tree.high_base = f.n - 1;
    tree.node_slots = f.n - 1 + (f.clusters - 1);
    tree.root = root;
    tree.primitives = f.n;
    tree.boxes = f.sorted.boxes.data();
    tree.boxes_by_triangle = true;
    tree.order = f.sorted.order.data();
    tree.leaf_runs = f.leaf_runs.data();
    tree.sparse_slots = true;  // leaf runs leave most split positions without a node
    return emit_raw_tree_on_device(tree, config, "HLBVH2", build, bvh);
}

// The raw tree for the host's refit and emission, timed into download_ms:
// the order, the references, the clusters (unless taken already: `found`
// null) and the top level; with `raw_boxes`, the boxes and level sizes of
// the raw forest too.
void download_forest(const ForestOnDevice& f, const Clusters* found, const ForestBoxes* raw_boxes,
                     BuildContext& build, DeviceHlbvh2Forest& out) {
    build.timer.start();
    out.forest.order = download_all(f.sorted.order, f.n);
    out.forest.refs = download_all(f.refs, f.ref_count());
    if (found != nullptr) {
        out.forest.cluster_begin = download_all(found->begin, f.clusters);
        out.forest.cluster_prefix = download_all(found->prefix, f.clusters);
    }
    out.forest.cluster_begin.push_back(f.n);
    if (f.clusters >= 2) out.forest.top_refs = download_all(f.top.top_refs, 2 * (size_t{f.clusters} - 1));
    if (raw_boxes != nullptr) {
        out.cluster_boxes = download_all(raw_boxes->clusters, f.clusters);
        out.level_sizes = f.level_sizes;
        if (f.clusters >= 2) out.top_boxes = download_all(f.top.top_boxes, f.clusters - 1);
        out.top_level_sizes = f.top.level_sizes;
    }
    build.stages.download_ms += build.timer.stop_ms();
}

// The device pipeline for n >= 2 triangles. `raw`: the raw forest comes
// back whole. Otherwise, with `config`, the device emits the BVH into `bvh`
// and returns true; false when it could not (too deep, or one leaf), and
// then the forest came back in `out`.
bool build_forest(std::span<const Triangle> triangles, uint32_t leaf_size, DeviceBuildStages& stages,
                  DeviceHlbvh2Forest& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr) {
    BuildContext build(stages);
    ForestOnDevice f;
    f.n = static_cast<uint32_t>(triangles.size());
    // 1. Boxes, bounds, codes, the sort.
    f.sorted = sort_triangles_by_morton_codes<uint32_t>(triangles, "HLBVH2", build);
    uint32_t root = f.n - 1;
    {
        // 2-5. The clusters and the boxes live in this scope: the device emission reads neither.
        Clusters found = find_clusters(f, leaf_size, build);
        std::vector<uint32_t> level_base;
        DeviceBuffer<uint32_t> level_nodes =
            build_bottom_levels(f, std::move(f.sorted.keys), std::move(found.queues), leaf_size, build, level_base);
        const ForestBoxes boxes = box_bottom_levels(f, std::move(level_nodes), level_base, build);
        if (f.clusters >= 2) f.top = build_top_level(f, found, boxes, build);
        stages.peak_device_bytes = build.meter.peak();
        if (!raw && f.clusters < 2) root = download_value(f.cluster_roots());
        if (raw || (root & hlbvh2::kLeafRef) != 0) {
            download_forest(f, &found, raw ? &boxes : nullptr, build, out);
            return false;
        }
        // The host's fallback gets the clusters from here.
        out.forest.cluster_begin = download_all(found.begin, f.clusters);
        out.forest.cluster_prefix = download_all(found.prefix, f.clusters);
    }
    // 6. Emission on the device.
    if (emit_on_device(f, root, *config, build, *bvh)) return true;
    download_forest(f, nullptr, nullptr, build, out);
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
