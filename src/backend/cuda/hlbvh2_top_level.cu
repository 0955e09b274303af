// HLBVH2's top level on the device (Garanzha 2014, dissertation ch. 5: the
// tree over the clusters by the grid-based SAH of ch. 4, §4.3, with the top
// grid only), building the CPU's tree (hlbvh2.cpp build_hlbvh2_top_level)
// from the shared steps of accel/bvh/builders/hlbvh2_top_steps.h:
//  1. one thread per cluster: its cell in the 32^3 grid, triangle count,
//     box and root, in cluster order; the root task (all clusters, node 0).
//  2. task queues, one launch per level: each warp takes 4 tasks with one
//     atomicAdd on the input queue's head (lane 0, broadcast by shuffle);
//     each task is processed by 8 lanes, as in ch. 4 (one lane per bin):
//     the cell bounds (strided over the clusters, a min/max reduction by
//     shuffles), the bin each lane owns on every axis, prefix and suffix
//     unions of the bins by shuffles (the box union is exact, so the bins
//     and areas are the CPU's), each lane's plane cost (rounded step by step:
//     the CPU's values), then every lane folds the 21 candidates in the CPU's
//     order (axis, then plane; the first kept unless a later one is strictly
//     cheaper). The clusters are partitioned stably into the other buffer
//     (ballot ranks within the task's 8 lanes, chunk by chunk), which is the
//     CPU's std::stable_partition, so the children's ranges and node numbers
//     are the CPU's; lone clusters' roots are written at once, and tasks of
//     >= 2 clusters are enqueued at a warp-local prefix (two ballots + popc)
//     after one atomicAdd per warp on the output tail. Cluster buffers and
//     queues ping-pong; no global scan.
//     Large tasks (more than kTopBlockTaskMin clusters: the first levels,
//     where the 8 lanes' binning is serial in the cluster count) have their
//     own queue and, per level, their own launch: one thread block per task,
//     its threads binning strided clusters into shared bins by integer
//     atomics on order-preserving float keys, 8 lanes choosing the split as
//     above, a block-wide scan (cub::BlockScan) ranking the stable
//     partition. The tree is the same: only who computes each step changes.
//  3. the top nodes' boxes bottom-up, one launch per level, deepest first.
#include <cuda_runtime.h>

#include <cub/block/block_scan.cuh>

#include <algorithm>
#include <string>
#include <vector>

#include "accel/bvh/builders/hlbvh2_top_steps.h"
#include "backend/cuda/hlbvh2_top_level.h"
#include "backend/cuda/launch.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

using hlbvh2::TopBin;
using hlbvh2::TopCluster;
using hlbvh2::TopTask;

constexpr uint32_t kWarp = 32;  // kBlockSize (launch.h) is a multiple: full-mask ballots are valid
constexpr uint32_t kFullMask = 0xffffffffu;
constexpr uint32_t kLanes = hlbvh2::kTopLanes;     // threads per task
constexpr uint32_t kTasksPerWarp = kWarp / kLanes;
constexpr uint32_t kMaxQueueBlocks = 1024;         // warps loop over the queue beyond this
constexpr uint32_t kTopTaskBlock = 256;            // threads per large task (the block path)
constexpr uint32_t kTaskBlockWarps = kTopTaskBlock / kWarp;
static_assert(kTopTaskBlock % kWarp == 0, "the block path's warps are full");
static_assert(kWarp % kLanes == 0, "tasks do not straddle warps");

// Stage 1: the clusters as top-level primitives, and the root task.
__global__ void top_clusters_kernel(DeviceTopLevelInput in, TopCluster* clusters, TopTask* root_task) {
    const uint32_t c = blockIdx.x * kBlockSize + threadIdx.x;
    if (c == 0) *root_task = TopTask{0, in.clusters, 0};
    if (c >= in.clusters) return;
    const uint32_t end = c + 1 < in.clusters ? in.cluster_begin[c + 1] : in.n;
    clusters[c] = TopCluster{in.cluster_boxes[c], hlbvh2::pack_cells(in.cluster_prefix[c]), end - in.cluster_begin[c],
                             in.cluster_roots[c]};
}

// Shuffles of a bin within a task's lanes (width kLanes).
__device__ TopBin shuffle_bin_up(uint32_t mask, const TopBin& b, uint32_t delta) {
    TopBin r;
    r.box.lo = Vec3f(__shfl_up_sync(mask, b.box.lo.x, delta, kLanes), __shfl_up_sync(mask, b.box.lo.y, delta, kLanes),
                     __shfl_up_sync(mask, b.box.lo.z, delta, kLanes));
    r.box.hi = Vec3f(__shfl_up_sync(mask, b.box.hi.x, delta, kLanes), __shfl_up_sync(mask, b.box.hi.y, delta, kLanes),
                     __shfl_up_sync(mask, b.box.hi.z, delta, kLanes));
    r.triangles = __shfl_up_sync(mask, b.triangles, delta, kLanes);
    r.clusters = __shfl_up_sync(mask, b.clusters, delta, kLanes);
    return r;
}
__device__ TopBin shuffle_bin_down(uint32_t mask, const TopBin& b, uint32_t delta) {
    TopBin r;
    r.box.lo = Vec3f(__shfl_down_sync(mask, b.box.lo.x, delta, kLanes),
                     __shfl_down_sync(mask, b.box.lo.y, delta, kLanes),
                     __shfl_down_sync(mask, b.box.lo.z, delta, kLanes));
    r.box.hi = Vec3f(__shfl_down_sync(mask, b.box.hi.x, delta, kLanes),
                     __shfl_down_sync(mask, b.box.hi.y, delta, kLanes),
                     __shfl_down_sync(mask, b.box.hi.z, delta, kLanes));
    r.triangles = __shfl_down_sync(mask, b.triangles, delta, kLanes);
    r.clusters = __shfl_down_sync(mask, b.clusters, delta, kLanes);
    return r;
}

// The split of a task from its bins, by its 8 lanes (`mask`: theirs;
// bins[axis]: the bin `lane` of each axis): prefix and suffix unions by
// shuffles, plane `lane`'s cost on each axis, then every lane folds the 21
// candidates in the CPU's order. Returns the same split on every lane and
// sets *left_count (count / 2 when there is no plane, as the CPU).
__device__ hlbvh2::TopSplit choose_split_lanes(uint32_t mask, uint32_t lane, const TopBin bins[3],
                                               const hlbvh2::CellBounds& bounds, uint32_t count,
                                               uint32_t* left_count) {
    // Plane `lane` of each axis: the bins below it against those from it on.
    float cost[3];
    bool valid[3];
    uint32_t left_clusters[3];
    for (int axis = 0; axis < 3; ++axis) {
        TopBin below = bins[axis], above = bins[axis];  // inclusive prefix and suffix
        for (uint32_t d = 1; d < kLanes; d *= 2) {
            const TopBin up = shuffle_bin_up(mask, below, d), down = shuffle_bin_down(mask, above, d);
            if (lane >= d) below = hlbvh2::merge_bins(up, below);
            if (lane + d < kLanes) above = hlbvh2::merge_bins(above, down);
        }
        TopBin left = shuffle_bin_up(mask, below, 1);
        if (lane == 0) left = TopBin{};
        cost[axis] = 0.0f;
        valid[axis] = lane >= 1 && lane < hlbvh2::axis_bins(bounds, axis) && hlbvh2::plane_cost(left, above, &cost[axis]);
        left_clusters[axis] = left.clusters;
    }
    // Every lane folds the candidates in the CPU's order: the same choice everywhere.
    hlbvh2::TopSplit split;
    *left_count = count / 2;  // no plane (clusters sharing a cell): halve, as the CPU
    for (int axis = 0; axis < 3; ++axis) {
        for (uint32_t plane = 1; plane < kLanes; ++plane) {
            const float c = __shfl_sync(mask, cost[axis], plane, kLanes);
            const bool v = __shfl_sync(mask, valid[axis] ? 1 : 0, plane, kLanes) != 0;
            const uint32_t lc = __shfl_sync(mask, left_clusters[axis], plane, kLanes);
            if (v && hlbvh2::consider(split, c, axis, plane)) *left_count = lc;
        }
    }
    return split;
}

// One task by its 8 lanes (`mask`: theirs; `lane`: 0..7 within the task).
// Returns, on every lane, the number of inner children to enqueue and
// fills `children` with them.
__device__ uint32_t process_top_task(uint32_t mask, uint32_t lane, uint32_t group, const TopTask& task,
                                     const TopCluster* in, TopCluster* out, uint32_t top_base, uint32_t* top_refs,
                                     TopTask children[2]) {
    const uint32_t count = task.end - task.first;
    // Cell bounds: strided partial bounds, then a butterfly min/max.
    hlbvh2::CellBounds bounds = hlbvh2::strided_cell_bounds(in, task.first, task.end, lane, kLanes);
    for (uint32_t d = kLanes / 2; d > 0; d /= 2) {
        hlbvh2::CellBounds other;
        for (int axis = 0; axis < 3; ++axis) {
            other.lo[axis] = __shfl_xor_sync(mask, bounds.lo[axis], d, kLanes);
            other.hi[axis] = __shfl_xor_sync(mask, bounds.hi[axis], d, kLanes);
        }
        hlbvh2::merge(bounds, other);
    }
    // This lane's bin on each axis.
    TopBin bins[3];
    hlbvh2::bin_task_lane(in, task.first, task.end, bounds, lane, bins);
    uint32_t left_count = 0;
    const hlbvh2::TopSplit split = choose_split_lanes(mask, lane, bins, bounds, count, &left_count);
    // Stable partition into `out`, 8 clusters at a time.
    const uint32_t right_count = count - left_count;
    const uint32_t below_lane = (1u << lane) - 1u;
    uint32_t lefts = 0;
    for (uint32_t chunk = task.first; chunk < task.end; chunk += kLanes) {
        const uint32_t i = chunk + lane;
        const bool has = i < task.end;
        TopCluster c;
        bool left = false;
        if (has) {
            c = in[i];
            left = hlbvh2::cluster_goes_left(c, i, task, bounds, split, left_count);
        }
        const uint32_t left_bits = (__ballot_sync(mask, left) >> (group * kLanes)) & ((1u << kLanes) - 1u);
        if (has) {
            const uint32_t lefts_before = lefts + static_cast<uint32_t>(__popc(left_bits & below_lane));
            out[hlbvh2::partition_slot(task, left_count, i, lefts_before, left)] = c;
            // A lone cluster is its side's child: its root is the reference.
            if (left && left_count == 1) top_refs[2 * task.node] = c.root;
            if (!left && right_count == 1) top_refs[2 * task.node + 1] = c.root;
        }
        lefts += static_cast<uint32_t>(__popc(left_bits));
    }
    hlbvh2::TopTask halves[2];
    hlbvh2::child_tasks(task, left_count, halves);
    uint32_t inner = 0;
    for (int side = 0; side < 2; ++side) {
        if (halves[side].end - halves[side].first < 2) continue;
        if (lane == 0) top_refs[2 * task.node + side] = top_base + halves[side].node;
        children[inner++] = halves[side];
    }
    return inner;
}

// Stage 2a: the level's small tasks (at most kTopBlockTaskMin clusters:
// their children are small too). counters[0]: the input head, counters[1]:
// the small output tail; both zero at launch. Clusters of the level's tasks
// are read from `in` and partitioned into `out`.
__global__ void top_level_kernel(const TopCluster* in, TopCluster* out, const TopTask* input, uint32_t count,
                                 TopTask* output, uint32_t* counters, uint32_t top_base, uint32_t* top_refs,
                                 uint32_t* level_nodes) {
    const uint32_t warp_lane = threadIdx.x % kWarp;
    const uint32_t group = warp_lane / kLanes, lane = warp_lane % kLanes;
    const uint32_t group_mask = ((1u << kLanes) - 1u) << (group * kLanes);
    for (;;) {
        uint32_t base = 0;
        if (warp_lane == 0) base = atomicAdd(&counters[0], kTasksPerWarp);  // one dequeue per warp
        base = __shfl_sync(kFullMask, base, 0);
        if (base >= count) return;  // uniform over the warp
        const uint32_t at = base + group;
        TopTask children[2];
        uint32_t inner = 0;
        if (at < count) {  // uniform over the task's lanes
            const TopTask task = input[at];
            inner = process_top_task(group_mask, lane, group, task, in, out, top_base, top_refs, children);
            if (lane == 0) level_nodes[at] = task.node;
        }
        // The task's lane 0 enqueues its children.
        const bool leader = lane == 0;
        const uint32_t one_or_more = __ballot_sync(kFullMask, leader && inner >= 1);
        const uint32_t two = __ballot_sync(kFullMask, leader && inner == 2);
        const uint32_t total = hlbvh2::enqueue_total(one_or_more, two);
        uint32_t out_base = 0;
        if (warp_lane == 0 && total != 0) out_base = atomicAdd(&counters[1], total);  // one enqueue per warp
        out_base = __shfl_sync(kFullMask, out_base, 0);
        if (leader) {
            const uint32_t offset = out_base + hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(warp_lane));
            for (uint32_t k = 0; k < inner; ++k) output[offset + k] = children[k];
        }
    }
}

// The block path's shared-memory atomics for strided_bin_keys.
struct SharedAtomics {
    __device__ void min(uint32_t* word, uint32_t value) const { atomicMin(word, value); }
    __device__ void max(uint32_t* word, uint32_t value) const { atomicMax(word, value); }
    __device__ void add(uint32_t* word, uint32_t value) const { atomicAdd(word, value); }
};

// Stage 2b: the level's large tasks (more than kTopBlockTaskMin clusters),
// one thread block each (large_input[blockIdx.x]). Every thread bins a
// strided share of the clusters into its warp's shared bins (integer-key
// atomics: exact, so any order gives bin_task's bins up to zero signs; a
// bin set per warp spreads the contention), the 8 lanes of warp 0 merge the
// warps' bins and choose the split as the small path does, then the block
// partitions stably, kTopTaskBlock clusters at a time, each cluster's slot
// from a block-wide exclusive scan of the left flags. Children of more than
// kTopBlockTaskMin clusters go to the next level's large queue, the others
// to its small queue: one atomicAdd on each tail used.
__global__ void __launch_bounds__(kTopTaskBlock) top_large_task_kernel(
    const TopCluster* in, TopCluster* out, const TopTask* large_input, TopTask* small_output, TopTask* large_output,
    uint32_t* counters, uint32_t top_base, uint32_t* top_refs, uint32_t* level_nodes) {
    using BlockScan = cub::BlockScan<uint32_t, kTopTaskBlock>;
    __shared__ hlbvh2::TopBinKeys warp_bins[kTaskBlockWarps][3][hlbvh2::kTopBins];
    __shared__ uint32_t cell_lo[3], cell_hi[3];
    __shared__ hlbvh2::TopSplit shared_split;
    __shared__ uint32_t shared_left_count;
    __shared__ typename BlockScan::TempStorage scan_storage;

    const uint32_t tid = threadIdx.x, warp = tid / kWarp, warp_lane = tid % kWarp;
    const TopTask task = large_input[blockIdx.x];
    const uint32_t count = task.end - task.first;
    hlbvh2::TopBinKeys* flat_bins = &warp_bins[0][0][0];
    for (uint32_t b = tid; b < kTaskBlockWarps * 3 * hlbvh2::kTopBins; b += kTopTaskBlock) {
        flat_bins[b] = hlbvh2::empty_bin_keys();
    }
    if (tid < 3) {
        cell_lo[tid] = hlbvh2::kTopGrid;
        cell_hi[tid] = 0;
    }
    __syncthreads();
    // Cell bounds: strided, a warp butterfly, one shared atomic per warp and axis.
    hlbvh2::CellBounds bounds = hlbvh2::strided_cell_bounds(in, task.first, task.end, tid, kTopTaskBlock);
    for (uint32_t d = kWarp / 2; d > 0; d /= 2) {
        hlbvh2::CellBounds other;
        for (int axis = 0; axis < 3; ++axis) {
            other.lo[axis] = __shfl_xor_sync(kFullMask, bounds.lo[axis], d);
            other.hi[axis] = __shfl_xor_sync(kFullMask, bounds.hi[axis], d);
        }
        hlbvh2::merge(bounds, other);
    }
    if (warp_lane == 0) {
        for (int axis = 0; axis < 3; ++axis) {
            atomicMin(&cell_lo[axis], bounds.lo[axis]);
            atomicMax(&cell_hi[axis], bounds.hi[axis]);
        }
    }
    __syncthreads();
    for (int axis = 0; axis < 3; ++axis) {
        bounds.lo[axis] = cell_lo[axis];
        bounds.hi[axis] = cell_hi[axis];
    }
    SharedAtomics atomics;
    hlbvh2::strided_bin_keys(in, task.first, task.end, tid, kTopTaskBlock, bounds, warp_bins[warp], atomics);
    __syncthreads();
    if (tid < kLanes) {  // lanes 0..7 of warp 0: lane `tid` owns bin `tid` of each axis
        TopBin bins[3];
        for (int axis = 0; axis < 3; ++axis) {
            hlbvh2::TopBinKeys keys = warp_bins[0][axis][tid];
            for (uint32_t w = 1; w < kTaskBlockWarps; ++w) hlbvh2::merge_keys(keys, warp_bins[w][axis][tid]);
            bins[axis] = hlbvh2::decode_bin(keys);
        }
        uint32_t left_count = 0;
        const hlbvh2::TopSplit split =
            choose_split_lanes((1u << kLanes) - 1u, tid, bins, bounds, count, &left_count);
        if (tid == 0) {
            shared_split = split;
            shared_left_count = left_count;
        }
    }
    __syncthreads();
    const hlbvh2::TopSplit split = shared_split;
    const uint32_t left_count = shared_left_count, right_count = count - left_count;
    // Stable partition into `out`, a block's worth of clusters at a time.
    uint32_t lefts = 0;
    for (uint32_t chunk = task.first; chunk < task.end; chunk += kTopTaskBlock) {
        const uint32_t i = chunk + tid;
        const bool has = i < task.end;
        TopCluster c;
        bool left = false;
        if (has) {
            c = in[i];
            left = hlbvh2::cluster_goes_left(c, i, task, bounds, split, left_count);
        }
        uint32_t before = 0, chunk_lefts = 0;
        BlockScan(scan_storage).ExclusiveSum(left ? 1u : 0u, before, chunk_lefts);
        if (has) {
            out[hlbvh2::partition_slot(task, left_count, i, lefts + before, left)] = c;
            if (left && left_count == 1) top_refs[2 * task.node] = c.root;
            if (!left && right_count == 1) top_refs[2 * task.node + 1] = c.root;
        }
        lefts += chunk_lefts;
        __syncthreads();  // the scan's storage is reused by the next chunk
    }
    if (tid == 0) {
        level_nodes[blockIdx.x] = task.node;
        TopTask halves[2];
        hlbvh2::child_tasks(task, left_count, halves);
        bool large[2] = {false, false}, inner[2] = {false, false};
        uint32_t large_count = 0, small_count = 0;
        for (int side = 0; side < 2; ++side) {
            const uint32_t size = halves[side].end - halves[side].first;
            if (size < 2) continue;
            top_refs[2 * task.node + side] = top_base + halves[side].node;
            inner[side] = true;
            large[side] = size > hlbvh2::kTopBlockTaskMin;
            if (large[side]) {
                ++large_count;
            } else {
                ++small_count;
            }
        }
        uint32_t small_at = small_count != 0 ? atomicAdd(&counters[1], small_count) : 0;
        uint32_t large_at = large_count != 0 ? atomicAdd(&counters[2], large_count) : 0;
        for (int side = 0; side < 2; ++side) {
            if (!inner[side]) continue;
            if (large[side]) {
                large_output[large_at++] = halves[side];
            } else {
                small_output[small_at++] = halves[side];
            }
        }
    }
}

// Stage 3: one level's top boxes; the deeper levels are final.
__global__ void top_boxes_kernel(hlbvh2::TopBoxView view, const uint32_t* level_nodes, uint32_t count) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < count) hlbvh2::top_node_box(view, level_nodes[i]);
}

// The top levels' ping-pong buffers: side s holds a level's input, 1 - s
// its output.
struct TopQueues {
    DeviceBuffer<TopCluster> clusters[2];
    DeviceBuffer<TopTask> small[2], large[2];
    DeviceBuffer<uint32_t> counters;  // small head, small tail, large tail
    uint32_t small_capacity = 0, large_capacity = 0;
};

TopQueues make_top_queues(uint32_t clusters, MemoryMeter& meter) {
    TopQueues q;
    // Tasks hold >= 2 clusters each, disjoint: a level has at most clusters / 2
    // small ones and clusters / (kTopBlockTaskMin + 1) large ones.
    q.small_capacity = clusters / 2;
    q.large_capacity = std::max(1u, clusters / (hlbvh2::kTopBlockTaskMin + 1));
    const char* const side_name[2] = {"A", "B"};
    for (int s = 0; s < 2; ++s) {
        q.clusters[s] = DeviceBuffer<TopCluster>(meter, std::string("HLBVH2: top clusters ") + side_name[s], clusters);
        q.small[s] =
            DeviceBuffer<TopTask>(meter, std::string("HLBVH2: top task queue ") + side_name[s], q.small_capacity);
        q.large[s] =
            DeviceBuffer<TopTask>(meter, std::string("HLBVH2: top large task queue ") + side_name[s], q.large_capacity);
    }
    q.counters = DeviceBuffer<uint32_t>(meter, "HLBVH2: top queue counters", 3);
    return q;
}

// One level from side `side`: its large tasks' nodes first, then its small
// tasks', at level_nodes.
void launch_top_level(TopQueues& q, int side, uint32_t small, uint32_t large, uint32_t top_base, uint32_t* top_refs,
                      uint32_t* level_nodes) {
    const int next = 1 - side;
    if (large != 0) {
        launch_shaped(top_large_task_kernel, {large, kTopTaskBlock}, q.clusters[side].data(), q.clusters[next].data(),
                      q.large[side].data(), q.small[next].data(), q.large[next].data(), q.counters.data(), top_base,
                      top_refs, level_nodes);
    }
    if (small != 0) {
        const uint32_t warps = (small + kTasksPerWarp - 1) / kTasksPerWarp;
        launch_shaped(top_level_kernel, {strided_blocks_for(uint64_t{warps} * kWarp, kMaxQueueBlocks)},
                      q.clusters[side].data(), q.clusters[next].data(), q.small[side].data(), small,
                      q.small[next].data(), q.counters.data(), top_base, top_refs, level_nodes + large);
    }
}

// Stages 1-2, timed as top_ms: the clusters as top-level primitives, then
// the task-queue levels, their nodes into `level_nodes` and their sizes into
// out.level_sizes. Returns each level's first index in `level_nodes`; the
// queues are freed on return.
std::vector<uint32_t> split_top_levels(const DeviceTopLevelInput& in, uint32_t* level_nodes, BuildContext& build,
                                       DeviceTopLevel& out) {
    const uint32_t top_nodes = in.clusters - 1, top_base = in.n - 1;
    TopQueues q = make_top_queues(in.clusters, build.meter);
    build.timer.start();
    const bool root_is_large = in.clusters > hlbvh2::kTopBlockTaskMin;
    launch(top_clusters_kernel, in.clusters, in, q.clusters[0].data(),
           root_is_large ? q.large[0].data() : q.small[0].data());
    std::vector<uint32_t> level_base;
    out.level_sizes.clear();
    uint32_t small = root_is_large ? 0 : 1, large = root_is_large ? 1 : 0, base = 0;
    int side = 0;  // the level's input clusters and queues
    while (small + large != 0) {
        const uint32_t count = small + large;
        if (base + size_t{count} > top_nodes) throw Error("HLBVH2: top levels overran their node list");
        out.level_sizes.push_back(count);
        level_base.push_back(base);
        RF_CUDA_CHECK(cudaMemsetAsync(q.counters.data(), 0, q.counters.bytes()));
        launch_top_level(q, side, small, large, top_base, out.top_refs.data(), level_nodes + base);
        base += count;
        uint32_t next[3] = {};  // the next level's sizes (waits for this one)
        RF_CUDA_CHECK(cudaMemcpy(next, q.counters.data(), sizeof next, cudaMemcpyDeviceToHost));
        small = next[1];
        large = next[2];
        if (small > q.small_capacity || large > q.large_capacity) throw Error("HLBVH2: top task queue overflow");
        side = 1 - side;
    }
    if (base != top_nodes) throw Error("HLBVH2: the top levels made the wrong number of nodes");
    build.stages.top_ms = build.timer.stop_ms();
    build.stages.top_levels = static_cast<uint32_t>(out.level_sizes.size());
    return level_base;
}

}  // namespace

DeviceTopLevel build_top_level_on_device(const DeviceTopLevelInput& in, BuildContext& build) {
    if (in.clusters < 2) throw Error("HLBVH2 device top level: fewer than 2 clusters");
    const uint32_t top_nodes = in.clusters - 1;
    DeviceTopLevel out;
    out.top_refs = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: top-level child references", 2 * size_t{top_nodes});
    out.top_boxes = DeviceBuffer<Box3f>(build.meter, "HLBVH2: top node boxes", top_nodes);
    // Every task is a distinct top node.
    DeviceBuffer<uint32_t> level_nodes(build.meter, "HLBVH2: top level nodes", top_nodes);
    const std::vector<uint32_t> level_base = split_top_levels(in, level_nodes.data(), build, out);

    // 3. The top nodes' boxes bottom-up, deepest level first.
    const hlbvh2::TopBoxView view{in.bottom, out.top_refs.data(), in.n - 1, out.top_boxes.data()};
    build.timer.start();
    for (size_t l = out.level_sizes.size(); l-- > 0;) {
        launch(top_boxes_kernel, out.level_sizes[l], view, level_nodes.data() + level_base[l], out.level_sizes[l]);
    }
    build.stages.boxes_ms += build.timer.stop_ms();
    return out;
}

}  // namespace rf::cuda
