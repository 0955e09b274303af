// HLBVH2's top level on the device (Garanzha 2014, dissertation ch. 5: the
// tree over the clusters by the grid-based SAH of ch. 4, §4.3, with the top
// grid only), building the CPU's tree (hlbvh2.cpp build_hlbvh2_top_level)
// from the shared steps of accel/bvh/builders/hlbvh2_top_steps.h:
// Steps 1 and 2 are ONE cooperative launch (top_level_kernel: every block
// resident, a cooperative_groups grid sync after step 1 and after each
// level; no host look at any level):
//  1. grid-strided over the clusters: each one's cell in the 32^3 grid,
//     triangle count, box and root, in cluster order; the root task (all
//     clusters, node 0) in level 0's record.
//  2. task queues, level after level, each level reading its sizes from its
//     record on the device (hlbvh2::TopQueueLevel, zeroed once), block 0
//     opening the next record: each warp takes 4 small tasks with one
//     atomicAdd on the input queue's head (lane 0, broadcast by shuffle);
//     each task is processed by 8 lanes, as in ch. 4 (one lane per bin):
//     the cell bounds (strided over the clusters, a min/max reduction by
//     shuffles), the bin each lane owns on every axis (tasks of more than
//     32 clusters: strided binning and a reduce-scatter by xor shuffles,
//     not every lane reading every cluster), prefix and suffix
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
//     own queue: block b takes the level's large tasks b, b + gridDim.x, ...
//     (before its warps turn to the small queue), its threads binning
//     strided clusters into shared bins by integer atomics on
//     order-preserving float keys, 8 lanes choosing the split as above, a
//     block-wide scan (cub::BlockScan) ranking the stable partition. Large
//     and small tasks of a level run concurrently: they read the level's
//     cluster buffer and write disjoint ranges of the other. The tree is the
//     same: only who computes each step changes. The grid is as wide as the
//     widest level needs, capped at the blocks that can be resident.
//  3. the top nodes' boxes bottom-up in one launch (after one that links
//     each top node to its parent): one thread per top node, the walks
//     starting at the nodes with a cluster child, an arrival counter per
//     node letting the second walk go on (Karras 2012 sec. 4;
//     hlbvh2_top_steps.h top_boxes_from_node); the boxes are the level-wise
//     pass's, union(left, right) at every node.
#include <cuda_runtime.h>

#include <cooperative_groups.h>
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

namespace cg = cooperative_groups;
using hlbvh2::TopBin;
using hlbvh2::TopCluster;
using hlbvh2::TopTask;

constexpr uint32_t kWarp = 32;  // kBlockSize (launch.h) is a multiple: full-mask ballots are valid
constexpr uint32_t kFullMask = 0xffffffffu;
constexpr uint32_t kLanes = hlbvh2::kTopLanes;     // threads per task
constexpr uint32_t kTasksPerWarp = kWarp / kLanes;
constexpr uint32_t kTopTaskBlock = 256;            // threads per large task (the block path)
constexpr uint32_t kTaskBlockWarps = kTopTaskBlock / kWarp;
constexpr uint32_t kTasksPerBlock = kTaskBlockWarps * kTasksPerWarp;  // small tasks per block and dequeue round
static_assert(kTopTaskBlock % kWarp == 0, "the block path's warps are full");
static_assert(kWarp % kLanes == 0, "tasks do not straddle warps");

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

__device__ TopBin shuffle_bin_xor(uint32_t mask, const TopBin& b, uint32_t delta) {
    TopBin r;
    r.box.lo = Vec3f(__shfl_xor_sync(mask, b.box.lo.x, delta, kLanes), __shfl_xor_sync(mask, b.box.lo.y, delta, kLanes),
                     __shfl_xor_sync(mask, b.box.lo.z, delta, kLanes));
    r.box.hi = Vec3f(__shfl_xor_sync(mask, b.box.hi.x, delta, kLanes), __shfl_xor_sync(mask, b.box.hi.y, delta, kLanes),
                     __shfl_xor_sync(mask, b.box.hi.z, delta, kLanes));
    r.triangles = __shfl_xor_sync(mask, b.triangles, delta, kLanes);
    r.clusters = __shfl_xor_sync(mask, b.clusters, delta, kLanes);
    return r;
}

// Bin `lane` of each axis for a task of more than kTopStridedBinMin
// clusters: strided binning, then the reduce-scatter by xor shuffles
// (hlbvh2_top_steps.h strided_bins_lane, scatter_*).
__device__ void strided_bins_lanes(uint32_t mask, uint32_t lane, const TopCluster* in, const TopTask& task,
                                   const hlbvh2::CellBounds& bounds, TopBin out[3]) {
    TopBin all[3][hlbvh2::kTopBins];
    hlbvh2::strided_bins_lane(in, task.first, task.end, bounds, lane, all);
    for (uint32_t d = kLanes / 2; d > 0; d /= 2) {
        for (uint32_t j = 0; j < d; ++j) {
            const uint32_t k = hlbvh2::scatter_pair(lane, d, j);
            for (int axis = 0; axis < 3; ++axis) {
                const TopBin received = shuffle_bin_xor(mask, all[axis][hlbvh2::scatter_sent(lane, d, k)], d);
                TopBin& kept = all[axis][hlbvh2::scatter_kept(lane, d, k)];
                kept = hlbvh2::merge_bins(kept, received);
            }
        }
    }
    for (int axis = 0; axis < 3; ++axis) out[axis] = all[axis][lane];
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
    if (count > hlbvh2::kTopStridedBinMin) {
        strided_bins_lanes(mask, lane, in, task, bounds, bins);
    } else {
        hlbvh2::bin_task_lane(in, task.first, task.end, bounds, lane, bins);
    }
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

// Stage 2a: level `level`'s small tasks (at most kTopBlockTaskMin
// clusters: their children are small too), their number and place read
// from levels[level], their children counted into levels[level + 1].
// Clusters of the level's tasks are read from `in` and partitioned into `out`.
__device__ void small_tasks_of_level(const TopCluster* in, TopCluster* out, const TopTask* input, TopTask* output,
                                     const hlbvh2::TopQueueLevel& self, uint32_t* head, uint32_t* tail,
                                     const hlbvh2::TopQueueCapacity& capacity, uint32_t top_base, uint32_t* top_refs,
                                     uint32_t* all_level_nodes) {
    const uint32_t count = self.small;
    uint32_t* level_nodes = all_level_nodes + self.base + self.large;  // after the level's large tasks
    const uint32_t warp_lane = threadIdx.x % kWarp;
    const uint32_t group = warp_lane / kLanes, lane = warp_lane % kLanes;
    const uint32_t group_mask = ((1u << kLanes) - 1u) << (group * kLanes);
    for (;;) {
        uint32_t base = 0;
        if (warp_lane == 0) base = atomicAdd(head, kTasksPerWarp);  // one dequeue per warp
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
        if (warp_lane == 0 && total != 0) out_base = atomicAdd(tail, total);  // one enqueue per warp
        out_base = __shfl_sync(kFullMask, out_base, 0);
        if (leader) {
            const uint32_t offset = out_base + hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(warp_lane));
            for (uint32_t k = 0; k < inner; ++k) {
                if (offset + k < capacity.small) output[offset + k] = children[k];  // else the next level faults
            }
        }
    }
}

// A level record other threads wrote or counted into (L1 bypassed: the
// counts are atomics at L2).
__device__ hlbvh2::TopQueueLevel load_record(const hlbvh2::TopQueueLevel* p) {
    const uint32_t* w = reinterpret_cast<const uint32_t*>(p);
    return hlbvh2::TopQueueLevel{__ldcg(w + 0), __ldcg(w + 1), __ldcg(w + 2), __ldcg(w + 3), __ldcg(w + 4)};
}

// The block path's shared-memory atomics for strided_bin_keys.
struct SharedAtomics {
    __device__ void min(uint32_t* word, uint32_t value) const { atomicMin(word, value); }
    __device__ void max(uint32_t* word, uint32_t value) const { atomicMax(word, value); }
    __device__ void add(uint32_t* word, uint32_t value) const { atomicAdd(word, value); }
};

// Stage 2b: one large task (more than kTopBlockTaskMin clusters) by the
// whole thread block (`slot`: its place in its level's large queue). Every
// thread bins a strided share of the clusters into its warp's shared bins
// (integer-key atomics: exact, so any order gives bin_task's bins up to
// zero signs; a bin set per warp spreads the contention), the 8 lanes of
// warp 0 merge the warps' bins and choose the split as the small path does,
// then the block partitions stably, kTopTaskBlock clusters at a time, each
// cluster's slot from a block-wide exclusive scan of the left flags.
// Children of more than kTopBlockTaskMin clusters go to the next level's
// large queue, the others to its small queue: one atomicAdd on each tail
// used. Every thread of the block calls it (it has barriers).
__device__ void large_task_by_block(const TopCluster* in, TopCluster* out, const TopTask& task, uint32_t slot,
                                    TopTask* small_output, TopTask* large_output, hlbvh2::TopQueueLevel* next,
                                    const hlbvh2::TopQueueCapacity& capacity, uint32_t top_base, uint32_t* top_refs,
                                    uint32_t* level_nodes) {
    using BlockScan = cub::BlockScan<uint32_t, kTopTaskBlock>;
    __shared__ hlbvh2::TopBinKeys warp_bins[kTaskBlockWarps][3][hlbvh2::kTopBins];
    __shared__ uint32_t cell_lo[3], cell_hi[3];
    __shared__ hlbvh2::TopSplit shared_split;
    __shared__ uint32_t shared_left_count;
    __shared__ typename BlockScan::TempStorage scan_storage;

    const uint32_t tid = threadIdx.x, warp = tid / kWarp, warp_lane = tid % kWarp;
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
        level_nodes[slot] = task.node;
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
        uint32_t small_at = small_count != 0 ? atomicAdd(&next->small, small_count) : 0;
        uint32_t large_at = large_count != 0 ? atomicAdd(&next->large, large_count) : 0;
        for (int side = 0; side < 2; ++side) {  // past a capacity: not written, and the next level faults
            if (!inner[side]) continue;
            if (large[side]) {
                if (large_at < capacity.large) large_output[large_at] = halves[side];
                ++large_at;
            } else {
                if (small_at < capacity.small) small_output[small_at] = halves[side];
                ++small_at;
            }
        }
    }
}

// The device arrays of the top level's one launch: the ping-pong buffers
// (side s holds a level's input, 1 - s its output) and the levels' records.
struct TopLevelArrays {
    TopCluster* clusters[2];
    TopTask* small[2];
    TopTask* large[2];
    hlbvh2::TopQueueLevel* levels;  // max_levels + 1, zeroed
    uint32_t max_levels;
    hlbvh2::TopQueueCapacity capacity;
    uint32_t top_base;
    uint32_t* top_refs;
    uint32_t* level_nodes;
};

// Stages 1-2: the whole top level in ONE cooperative launch (every block
// resident; cooperative_groups grid syncs between the steps). First the
// clusters as top-level primitives (grid-strided) and the root task in
// level 0's record; then level after level: each block takes the level's
// large tasks blockIdx.x, + gridDim.x, ... (a whole block each), every
// warp of the grid takes small tasks from the level's small queue (4 per
// dequeue), the children counted into the next record, which block 0's
// first thread opens; a grid sync ends the level. All blocks read the same
// record after the sync, so all stop at the same level: the first empty
// one, or a fault.
__global__ void __launch_bounds__(kTopTaskBlock) top_level_kernel(DeviceTopLevelInput in, TopLevelArrays a,
                                                                  bool root_is_large) {
    cg::grid_group grid = cg::this_grid();
    for (uint64_t c = grid.thread_rank(); c < in.clusters; c += grid.size()) {
        const uint32_t i = static_cast<uint32_t>(c);
        const uint32_t end = i + 1 < in.clusters ? in.cluster_begin[i + 1] : in.n;
        a.clusters[0][i] = TopCluster{in.cluster_boxes[i], hlbvh2::pack_cells(in.cluster_prefix[i]),
                                      end - in.cluster_begin[i], in.cluster_roots[i]};
    }
    if (grid.thread_rank() == 0) {
        (root_is_large ? a.large[0] : a.small[0])[0] = TopTask{0, in.clusters, 0};
        (root_is_large ? a.levels[0].large : a.levels[0].small) = 1;
    }
    grid.sync();
    for (uint32_t level = 0; level < a.max_levels; ++level) {
        const hlbvh2::TopQueueLevel self = load_record(a.levels + level);
        hlbvh2::TopQueueLevel* next = a.levels + level + 1;
        if (blockIdx.x == 0 && threadIdx.x == 0) hlbvh2::open_next_top_level(self, next, a.capacity);
        if (!hlbvh2::top_level_runs(self, a.capacity) || self.small + self.large == 0) return;  // grid-uniform
        const uint32_t side = level & 1;
        uint32_t* level_nodes = a.level_nodes + self.base;  // the level's large tasks first
        for (uint32_t t = blockIdx.x; t < self.large; t += gridDim.x) {  // uniform over the block
            large_task_by_block(a.clusters[side], a.clusters[1 - side], a.large[side][t], t, a.small[1 - side],
                                a.large[1 - side], next, a.capacity, a.top_base, a.top_refs, level_nodes);
        }
        small_tasks_of_level(a.clusters[side], a.clusters[1 - side], a.small[side], a.small[1 - side], self,
                             &a.levels[level].small_head, &next->small, a.capacity, a.top_base, a.top_refs,
                             a.level_nodes);
        grid.sync();  // the level's children, clusters and counts are final for every block
    }
}

// Stage 3a: the top nodes' parent links, one thread per top node.
__global__ void link_top_children_kernel(hlbvh2::TopBoxView view, uint32_t top_nodes, uint32_t* top_parent) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < top_nodes) hlbvh2::link_top_children(view, k, top_parent);
}

// Stage 3b: the top boxes bottom-up in one launch, one thread per top node
// (the walks start at the nodes with a cluster child).
__global__ void top_boxes_kernel(hlbvh2::TopBoxView view, const uint32_t* top_parent, uint32_t* arrivals,
                                 uint32_t top_nodes) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < top_nodes) hlbvh2::top_boxes_from_node<karras::AtomicArrival>(view, top_parent, arrivals, k);
}

// The top levels' ping-pong buffers: side s holds a level's input, 1 - s
// its output; the levels' records.
struct TopQueues {
    DeviceBuffer<TopCluster> clusters[2];
    DeviceBuffer<TopTask> small[2], large[2];
    DeviceBuffer<hlbvh2::TopQueueLevel> levels;  // max_levels + 1, zeroed
    hlbvh2::TopQueueCapacity capacity{};
    uint32_t max_levels = 0;
};

// Allocated and zeroed outside the timed stages.
TopQueues make_top_queues(uint32_t clusters, MemoryMeter& meter) {
    TopQueues q;
    // Tasks hold >= 2 clusters each, disjoint: a level has at most clusters / 2
    // small ones and clusters / (kTopBlockTaskMin + 1) large ones; every
    // level makes at least one of the clusters - 1 top nodes.
    q.capacity.small = clusters / 2;
    q.capacity.large = std::max(1u, clusters / (hlbvh2::kTopBlockTaskMin + 1));
    q.capacity.nodes = clusters - 1;
    q.max_levels = clusters;
    const char* const side_name[2] = {"A", "B"};
    for (int s = 0; s < 2; ++s) {
        q.clusters[s] = DeviceBuffer<TopCluster>(meter, std::string("HLBVH2: top clusters ") + side_name[s], clusters);
        q.small[s] =
            DeviceBuffer<TopTask>(meter, std::string("HLBVH2: top task queue ") + side_name[s], q.capacity.small);
        q.large[s] =
            DeviceBuffer<TopTask>(meter, std::string("HLBVH2: top large task queue ") + side_name[s], q.capacity.large);
    }
    q.levels = DeviceBuffer<hlbvh2::TopQueueLevel>(meter, "HLBVH2: top level records", size_t{q.max_levels} + 1);
    RF_CUDA_CHECK(cudaMemset(q.levels.data(), 0, q.levels.bytes()));
    return q;
}

// The cooperative launch's grid: enough blocks for the widest level (its
// large tasks a block each, its small tasks 4 per warp), at most as many as
// can be resident at once (a grid sync needs every block resident).
uint32_t top_level_grid(const hlbvh2::TopQueueCapacity& capacity) {
    int device = 0, cooperative = 0, multiprocessors = 0, per_multiprocessor = 0;
    RF_CUDA_CHECK(cudaGetDevice(&device));
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&cooperative, cudaDevAttrCooperativeLaunch, device));
    if (cooperative == 0) throw Error("HLBVH2 device top level: the device has no cooperative launches");
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&multiprocessors, cudaDevAttrMultiProcessorCount, device));
    RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_multiprocessor, top_level_kernel,
                                                                static_cast<int>(kTopTaskBlock), 0));
    const uint64_t resident = uint64_t(std::max(per_multiprocessor, 1)) * uint64_t(std::max(multiprocessors, 1));
    const uint64_t small_blocks = (uint64_t{capacity.small} + kTasksPerBlock - 1) / kTasksPerBlock;
    const uint64_t wanted = std::max<uint64_t>({uint64_t{capacity.large}, small_blocks, 1});
    return static_cast<uint32_t>(std::min(wanted, resident));
}

// Stages 1-2, timed as top_ms: the clusters as top-level primitives and
// every task-queue level in one cooperative launch, their nodes into
// `level_nodes`. The records come back once: out.level_sizes. The queues
// are freed on return.
void split_top_levels(const DeviceTopLevelInput& in, uint32_t* level_nodes, BuildContext& build, DeviceTopLevel& out) {
    const uint32_t top_nodes = in.clusters - 1;
    TopQueues q = make_top_queues(in.clusters, build.meter);
    TopLevelArrays arrays{{q.clusters[0].data(), q.clusters[1].data()},
                          {q.small[0].data(), q.small[1].data()},
                          {q.large[0].data(), q.large[1].data()},
                          q.levels.data(),
                          q.max_levels,
                          q.capacity,
                          in.n - 1,
                          out.top_refs.data(),
                          level_nodes};
    DeviceTopLevelInput input = in;
    bool root_is_large = in.clusters > hlbvh2::kTopBlockTaskMin;
    void* args[] = {&input, &arrays, &root_is_large};
    const uint32_t grid = top_level_grid(q.capacity);
    build.timer.start();
    RF_CUDA_CHECK(cudaLaunchCooperativeKernel(reinterpret_cast<const void*>(top_level_kernel), dim3(grid),
                                              dim3(kTopTaskBlock), args, 0, cudaStream_t{}));
    build.stages.top_ms = build.timer.stop_ms();
    std::vector<hlbvh2::TopQueueLevel> records(size_t{q.max_levels} + 1);  // those past the last level stay empty
    q.levels.download(records);
    std::vector<uint32_t> level_base;
    out.level_sizes.clear();
    for (const hlbvh2::TopQueueLevel& r : records) {
        if (r.fault != 0) throw Error("HLBVH2: a top level overflowed its task queues (device fault)");
        if (r.small + r.large == 0) break;
        out.level_sizes.push_back(r.small + r.large);
        level_base.push_back(r.base);
    }
    const uint32_t made = level_base.empty() ? 0 : level_base.back() + out.level_sizes.back();
    if (made != top_nodes || records.back().small + records.back().large != 0) {
        throw Error("HLBVH2: the top levels made " + std::to_string(made) + " nodes, not " +
                    std::to_string(top_nodes));
    }
    build.stages.top_levels = static_cast<uint32_t>(out.level_sizes.size());
}

}  // namespace

DeviceTopLevel build_top_level_on_device(const DeviceTopLevelInput& in, BuildContext& build) {
    if (in.clusters < 2) throw Error("HLBVH2 device top level: fewer than 2 clusters");
    const uint32_t top_nodes = in.clusters - 1;
    DeviceTopLevel out;
    out.top_refs = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: top-level child references", 2 * size_t{top_nodes});
    out.top_boxes = DeviceBuffer<Box3f>(build.meter, "HLBVH2: top node boxes", top_nodes);
    {
        // Every task is a distinct top node.
        DeviceBuffer<uint32_t> level_nodes(build.meter, "HLBVH2: top level nodes", top_nodes);
        split_top_levels(in, level_nodes.data(), build, out);
    }

    // 3. The top nodes' boxes bottom-up: their parent links, then one pass with arrival counters.
    const hlbvh2::TopBoxView view{in.bottom, out.top_refs.data(), in.n - 1, out.top_boxes.data()};
    DeviceBuffer<uint32_t> top_parent(build.meter, "HLBVH2: top node parents", top_nodes);
    DeviceBuffer<uint32_t> arrivals(build.meter, "HLBVH2: top node arrival counters", top_nodes);
    build.timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    launch(link_top_children_kernel, top_nodes, view, top_nodes, top_parent.data());
    launch(top_boxes_kernel, top_nodes, view, top_parent.data(), arrivals.data(), top_nodes);
    build.stages.boxes_ms += build.timer.stop_ms();
    return out;
}

}  // namespace rf::cuda
