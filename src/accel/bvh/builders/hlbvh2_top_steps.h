// The per-task steps of HLBVH2's top level (Garanzha 2014, dissertation
// ch. 5, which builds the tree over the clusters with the grid-based SAH of
// ch. 4, §4.3, using the top grid only), written once for both backends: the
// CPU builder (hlbvh2.cpp) recurses over them, the CUDA builder
// (backend/cuda/hlbvh2_top_level.cu) runs them by task queues, every level
// in one cooperative launch, kTopLanes threads per task (ch. 4: 8 threads,
// one per bin).
//
// A cluster is an indivisible primitive: its cell in the 32^3 grid of the
// 15-bit Morton prefixes, its triangle count, box and bottom-tree root. A
// task is a range of clusters [first, end) (>= 2 of them) and its node
// number k; it becomes top node top_base + k ("top nodes numbered by their
// cluster ranges": the node over a range of m clusters owns the numbers
// k .. k + m - 2, its left child k + 1, its right child k + left count).
//  - cell bounds: the integer cell bounds of the task's clusters per axis;
//    an axis spanning c >= 2 cells gets min(8, c) bins, cell x going to bin
//    (x - lo) * bins / c; the candidate planes lie between bins.
//  - bins: box, triangles and clusters per bin (bin_task: all bins of a task,
//    sequentially; bin_task_lane: the bin a device lane owns, of each axis;
//    strided_bins_lane + the scatter_* steps: for tasks of more than
//    kTopStridedBinMin clusters, a lane bins every 8th cluster and a
//    reduce-scatter by shuffles hands each lane its bin).
//  - plane_cost(): area(L) * triangles(L) + area(R) * triangles(R) (half
//    areas), rounded step by step with no fused multiply-add on either
//    backend, so both evaluate the same costs bit for bit.
//  - consider(): the split choice with the CPU's tie rules: axes x, y, z,
//    planes left to right, the first candidate kept unless a later one is
//    strictly cheaper (so a NaN cost behaves the same on both backends too).
//  - partition: clusters left of the plane keep their order before those
//    right of it (a stable partition; the device ranks them by ballots).
//  - child_tasks(): the children's ranges and node numbers.
//  - link_top_children(), top_boxes_from_node(): the device's bottom-up pass
//    over the top nodes' boxes, one launch with arrival counters.
//  - large tasks (more than kTopBlockTaskMin clusters) are run on the device
//    by a whole thread block: every thread bins a strided share of the
//    clusters into shared bins kept as integer keys (ordered_key: atomicMin /
//    atomicMax on keys are float min / max; counts by atomicAdd), merged
//    and decoded into TopBins for the split; then the stable partition by a
//    block-wide scan (partition_slot). The bins equal bin_task's up to the
//    sign of zero in a box bound, which never changes an extent's magnitude,
//    an area's or a cost's, nor the outcome of a comparison (-0 == +0).
// Child references are those of morton::RawTree: a bottom inner node index,
// kLeafRef | sorted position, or a top node's top_base + k.
// No std:: here: plain pointers, RF_HDI.
#pragma once

#include <cstdint>

#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "core/rounded_arithmetic.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf::hlbvh2 {

inline constexpr uint32_t kTopGrid = 32;  // 2^5 cells per axis: the 15-bit cluster prefixes
inline constexpr uint32_t kTopBins = 8;   // up to 8 bins (7 planes) per axis
inline constexpr uint32_t kTopLanes = 8;  // device threads per task: one per bin
static_assert(kTopLanes == kTopBins, "a device lane owns one bin per axis");
// Tasks of more clusters than this are binned and partitioned by a whole
// thread block on the device (256 threads: each has at least one cluster);
// at or below it, 8 lanes reading every cluster take a few hundred loads,
// less than a block's barriers and shared-memory setup cost.
inline constexpr uint32_t kTopBlockTaskMin = 256;

struct TopCluster {
    Box3f box;           // of its triangles
    uint32_t cells;      // x | y << 5 | z << 10
    uint32_t triangles;
    uint32_t root;       // its bottom tree's root reference
};

struct TopTask {
    uint32_t first;  // clusters [first, end), end - first >= 2
    uint32_t end;
    uint32_t node;   // its number k: top node top_base + k
};

// Cell of a 15-bit cluster prefix on one axis (x: bits 3k+2, y: 3k+1, z: 3k).
RF_HDI uint32_t prefix_cell(uint32_t prefix, int axis) {
    uint32_t cell = 0;
    for (int k = 0; k < 5; ++k) cell |= ((prefix >> (3 * k + 2 - axis)) & 1u) << k;
    return cell;
}
RF_HDI uint32_t pack_cells(uint32_t prefix) {
    return prefix_cell(prefix, 0) | (prefix_cell(prefix, 1) << 5) | (prefix_cell(prefix, 2) << 10);
}
RF_HDI uint32_t cell_of(uint32_t cells, int axis) { return (cells >> (5 * axis)) & (kTopGrid - 1); }

struct CellBounds {
    uint32_t lo[3];
    uint32_t hi[3];
};
RF_HDI CellBounds empty_cell_bounds() { return {{kTopGrid, kTopGrid, kTopGrid}, {0, 0, 0}}; }
RF_HDI void grow(CellBounds& b, uint32_t cells) {
    for (int axis = 0; axis < 3; ++axis) {
        const uint32_t c = cell_of(cells, axis);
        b.lo[axis] = c < b.lo[axis] ? c : b.lo[axis];
        b.hi[axis] = c > b.hi[axis] ? c : b.hi[axis];
    }
}
RF_HDI void merge(CellBounds& b, const CellBounds& o) {
    for (int axis = 0; axis < 3; ++axis) {
        b.lo[axis] = o.lo[axis] < b.lo[axis] ? o.lo[axis] : b.lo[axis];
        b.hi[axis] = o.hi[axis] > b.hi[axis] ? o.hi[axis] : b.hi[axis];
    }
}
// Bins on `axis`: 0 when the task spans one cell there (no plane).
RF_HDI uint32_t axis_bins(const CellBounds& b, int axis) {
    const uint32_t cells = b.hi[axis] - b.lo[axis] + 1;
    return cells < 2 ? 0u : (cells < kTopBins ? cells : kTopBins);
}
RF_HDI uint32_t bin_index(uint32_t cells, const CellBounds& b, int axis, uint32_t bins) {
    return (cell_of(cells, axis) - b.lo[axis]) * bins / (b.hi[axis] - b.lo[axis] + 1);
}

struct TopBin {
    Box3f box;  // empty while no cluster is in it
    uint32_t triangles = 0;
    uint32_t clusters = 0;
};
RF_HDI void add(TopBin& bin, const TopCluster& c) {
    bin.box = box_union(bin.box, c.box);
    bin.triangles += c.triangles;
    ++bin.clusters;
}
RF_HDI TopBin merge_bins(const TopBin& a, const TopBin& b) {
    TopBin r;
    r.box = box_union(a.box, b.box);
    r.triangles = a.triangles + b.triangles;
    r.clusters = a.clusters + b.clusters;
    return r;
}

// Half the surface area (morton::half_area's expression; boxes are never empty here).
RF_HDI float top_half_area(const Box3f& b) {
    const float x = b.hi.x - b.lo.x, y = b.hi.y - b.lo.y, z = b.hi.z - b.lo.z;
    return add_rn(add_rn(mul_rn(x, y), mul_rn(y, z)), mul_rn(z, x));
}

// The cost of a plane with `left` the union of the bins below it and `right`
// of those from it on; false when either side has no cluster.
RF_HDI bool plane_cost(const TopBin& left, const TopBin& right, float* cost) {
    if (left.clusters == 0 || right.clusters == 0) return false;
    *cost = add_rn(mul_rn(top_half_area(left.box), static_cast<float>(left.triangles)),
                   mul_rn(top_half_area(right.box), static_cast<float>(right.triangles)));
    return true;
}

struct TopSplit {
    float cost = 0.0f;
    int axis = -1;        // -1: none yet
    uint32_t plane = 0;   // clusters in bins below `plane` go left
};
// Candidates must come in the CPU's order: axis 0, 1, 2, planes ascending.
// True when the candidate is the best so far.
RF_HDI bool consider(TopSplit& best, float cost, int axis, uint32_t plane) {
    if (best.axis >= 0 && !(cost < best.cost)) return false;
    best.cost = cost;
    best.axis = axis;
    best.plane = plane;
    return true;
}

RF_HDI bool goes_left(const TopCluster& c, const CellBounds& b, const TopSplit& split) {
    return bin_index(c.cells, b, split.axis, axis_bins(b, split.axis)) < split.plane;
}

// The cell bounds of clusters first + lane, first + lane + stride, ... < end.
RF_HDI CellBounds strided_cell_bounds(const TopCluster* clusters, uint32_t first, uint32_t end, uint32_t lane,
                                      uint32_t stride) {
    CellBounds b = empty_cell_bounds();
    for (uint32_t i = first + lane; i < end; i += stride) grow(b, clusters[i].cells);
    return b;
}

// ---- The block path's shared bins ----

// A float as an unsigned key of the same order (negatives' bits inverted,
// positives' sign bit set): integer min / max of keys are float min / max
// for every non-NaN value, -0 ordering just below +0.
RF_HDI uint32_t ordered_key(float f) {
    const uint32_t u = float_to_bits(f);
    return (u & 0x80000000u) != 0 ? ~u : u | 0x80000000u;
}
RF_HDI float key_value(uint32_t key) {
    return bits_to_float((key & 0x80000000u) != 0 ? key & 0x7fffffffu : ~key);
}

// A bin as shared-memory words: box bounds as ordered keys, counts.
struct TopBinKeys {
    uint32_t lo[3];
    uint32_t hi[3];
    uint32_t triangles;
    uint32_t clusters;
};
// An empty bin: the keys of Box3f{}'s bounds (+-FLT_MAX, not infinities, so
// that min / max with infinite bounds keep bin_task's results).
RF_HDI TopBinKeys empty_bin_keys() {
    const Box3f empty{};
    return {{ordered_key(empty.lo.x), ordered_key(empty.lo.y), ordered_key(empty.lo.z)},
            {ordered_key(empty.hi.x), ordered_key(empty.hi.y), ordered_key(empty.hi.z)},
            0u,
            0u};
}
RF_HDI void merge_keys(TopBinKeys& a, const TopBinKeys& b) {
    for (int d = 0; d < 3; ++d) {
        a.lo[d] = b.lo[d] < a.lo[d] ? b.lo[d] : a.lo[d];
        a.hi[d] = b.hi[d] > a.hi[d] ? b.hi[d] : a.hi[d];
    }
    a.triangles += b.triangles;
    a.clusters += b.clusters;
}
RF_HDI TopBin decode_bin(const TopBinKeys& k) {
    TopBin bin;
    bin.box.lo = Vec3f(key_value(k.lo[0]), key_value(k.lo[1]), key_value(k.lo[2]));
    bin.box.hi = Vec3f(key_value(k.hi[0]), key_value(k.hi[1]), key_value(k.hi[2]));
    bin.triangles = k.triangles;
    bin.clusters = k.clusters;
    return bin;
}

// One block thread's share of a large task's binning: clusters first +
// thread, first + thread + stride, ... < end, each added to its bin of every
// axis with `atomics` (min, max, add on a uint32_t word: shared-memory
// atomics on the device, plain updates in the CPU's emulation).
template <class Atomics>
RF_HDI void strided_bin_keys(const TopCluster* clusters, uint32_t first, uint32_t end, uint32_t thread,
                             uint32_t stride, const CellBounds& b, TopBinKeys bins[3][kTopBins], Atomics& atomics) {
    uint32_t count[3];
    for (int axis = 0; axis < 3; ++axis) count[axis] = axis_bins(b, axis);
    for (uint32_t i = first + thread; i < end; i += stride) {
        const TopCluster& c = clusters[i];
        const uint32_t lo[3] = {ordered_key(c.box.lo.x), ordered_key(c.box.lo.y), ordered_key(c.box.lo.z)};
        const uint32_t hi[3] = {ordered_key(c.box.hi.x), ordered_key(c.box.hi.y), ordered_key(c.box.hi.z)};
        for (int axis = 0; axis < 3; ++axis) {
            if (count[axis] == 0) continue;
            TopBinKeys& bin = bins[axis][bin_index(c.cells, b, axis, count[axis])];
            for (int d = 0; d < 3; ++d) {
                atomics.min(&bin.lo[d], lo[d]);
                atomics.max(&bin.hi[d], hi[d]);
            }
            atomics.add(&bin.triangles, c.triangles);
            atomics.add(&bin.clusters, 1u);
        }
    }
}

// Which side cluster i of a task goes to: by the plane, or, with no plane
// (all clusters in one cell), the first left_count of them.
RF_HDI bool cluster_goes_left(const TopCluster& c, uint32_t i, const TopTask& task, const CellBounds& b,
                              const TopSplit& split, uint32_t left_count) {
    return split.axis >= 0 ? goes_left(c, b, split) : i - task.first < left_count;
}
// Where the stable partition puts cluster i, with lefts_before clusters of
// the task before it going left.
RF_HDI uint32_t partition_slot(const TopTask& task, uint32_t left_count, uint32_t i, uint32_t lefts_before, bool left) {
    return left ? task.first + lefts_before : task.first + left_count + (i - task.first - lefts_before);
}

// Every bin of a task, sequentially (the CPU): bins[axis][0 .. axis_bins).
RF_HDI void bin_task(const TopCluster* clusters, uint32_t first, uint32_t end, const CellBounds& b,
                     TopBin bins[3][kTopBins]) {
    uint32_t count[3];
    for (int axis = 0; axis < 3; ++axis) count[axis] = axis_bins(b, axis);
    for (uint32_t i = first; i < end; ++i) {
        for (int axis = 0; axis < 3; ++axis) {
            if (count[axis] != 0) add(bins[axis][bin_index(clusters[i].cells, b, axis, count[axis])], clusters[i]);
        }
    }
}

// The bin `lane` of each axis (a device lane's share: it reads every cluster
// of the task and keeps those in its bin; the box union is exact, so the
// bins equal bin_task's).
RF_HDI void bin_task_lane(const TopCluster* clusters, uint32_t first, uint32_t end, const CellBounds& b,
                          uint32_t lane, TopBin out[3]) {
    uint32_t count[3];
    for (int axis = 0; axis < 3; ++axis) count[axis] = axis_bins(b, axis);
    for (uint32_t i = first; i < end; ++i) {
        const uint32_t cells = clusters[i].cells;
        for (int axis = 0; axis < 3; ++axis) {
            if (count[axis] != 0 && bin_index(cells, b, axis, count[axis]) == lane) add(out[axis], clusters[i]);
        }
    }
}

// ---- The 8-lane path's strided binning (tasks of more than
// kTopStridedBinMin clusters) ----
// Lane `lane` bins clusters first + lane, first + lane + kTopLanes, ...
// into all its bins of every axis; a reduce-scatter over the task's 8
// lanes by xor shuffles (d = 4, 2, 1) then leaves lane L with bin L of
// each axis, summed over the lanes: at step d a lane keeps, of each pair of
// its remaining bins (k, k | d), the one that agrees with it in bit d and
// adds its partner's value of it. Each lane reads count / 8 clusters
// instead of all of them. The box union is exact, so the bins are
// bin_task's up to the sign of zero (as the block path's).
inline constexpr uint32_t kTopStridedBinMin = 32;

RF_HDI void strided_bins_lane(const TopCluster* clusters, uint32_t first, uint32_t end, const CellBounds& b,
                              uint32_t lane, TopBin bins[3][kTopBins]) {
    uint32_t count[3];
    for (int axis = 0; axis < 3; ++axis) count[axis] = axis_bins(b, axis);
    for (uint32_t i = first + lane; i < end; i += kTopLanes) {
        for (int axis = 0; axis < 3; ++axis) {
            if (count[axis] != 0) add(bins[axis][bin_index(clusters[i].cells, b, axis, count[axis])], clusters[i]);
        }
    }
}
// The j-th pair (k, k | d) at step d, j < d: k has bit d clear and the
// bits above it of `lane` (which its partner lane ^ d shares).
RF_HDI uint32_t scatter_pair(uint32_t lane, uint32_t d, uint32_t j) { return (lane & ~(2 * d - 1)) | j; }
RF_HDI uint32_t scatter_kept(uint32_t lane, uint32_t d, uint32_t k) { return (lane & d) != 0 ? (k | d) : k; }
RF_HDI uint32_t scatter_sent(uint32_t lane, uint32_t d, uint32_t k) { return (lane & d) != 0 ? k : (k | d); }

// The best plane over all axes from the bins, sequentially (the CPU).
// *left_clusters receives the clusters left of it.
RF_HDI TopSplit choose_split(const TopBin bins[3][kTopBins], const CellBounds& b, uint32_t* left_clusters) {
    TopSplit best;
    for (int axis = 0; axis < 3; ++axis) {
        const uint32_t count = axis_bins(b, axis);
        TopBin right[kTopBins];  // right[k]: bins k .. count - 1
        TopBin acc;
        for (uint32_t k = count; k-- > 1;) right[k] = acc = merge_bins(bins[axis][k], acc);
        acc = TopBin{};
        for (uint32_t k = 1; k < count; ++k) {
            acc = merge_bins(acc, bins[axis][k - 1]);
            float cost;
            if (plane_cost(acc, right[k], &cost) && consider(best, cost, axis, static_cast<uint32_t>(k))) {
                *left_clusters = acc.clusters;
            }
        }
    }
    return best;
}

// The children of a task whose first `left_count` clusters (after the
// partition) went left.
RF_HDI void child_tasks(const TopTask& task, uint32_t left_count, TopTask children[2]) {
    children[0] = TopTask{task.first, task.first + left_count, task.node + 1};
    children[1] = TopTask{task.first + left_count, task.end, task.node + left_count};
}

// The reference of a child task: a lone cluster's root, else its top node.
RF_HDI uint32_t child_reference(const TopTask& child, const TopCluster* partitioned, uint32_t top_base) {
    return child.end - child.first == 1 ? partitioned[child.first].root : top_base + child.node;
}

// What the device's bottom-up pass over the top nodes reads and writes.
struct TopBoxView {
    BoxView bottom;             // the bottom levels' boxes (final)
    const uint32_t* top_refs;   // 2 per top node: 2 k + side
    uint32_t top_base;          // top node k is node top_base + k (n - 1)
    Box3f* top_boxes;           // per top node k
};

RF_HDI bool is_top_reference(const TopBoxView& v, uint32_t ref) { return (ref & kLeafRef) == 0 && ref >= v.top_base; }

// The box of a top node's child: a top node's (another thread may have just
// written it: read past L1) or a cluster root's (final before the pass).
RF_HDI Box3f top_child_box(const TopBoxView& v, uint32_t ref) {
    if (is_top_reference(v, ref)) return karras::load_shared_box(&v.top_boxes[ref - v.top_base]);
    return reference_box(v.bottom, ref);
}

// The top nodes' parent links for the box pass, one thread per top node k:
// k records itself as its top children's parent; the root's is kNoParent.
RF_HDI void link_top_children(const TopBoxView& v, uint32_t k, uint32_t* top_parent) {
    if (k == 0) top_parent[0] = kNoParent;
    for (int side = 0; side < 2; ++side) {
        const uint32_t ref = v.top_refs[2 * k + side];
        if (is_top_reference(v, ref)) top_parent[ref - v.top_base] = k;
    }
}

// The top boxes bottom-up in one launch, one thread per top node k: the
// leaves of the top tree are the cluster roots, so a walk starts at each
// node with a cluster child (Karras 2012 sec. 4 with arrival counters, as
// the bottom trees' boxes_from_leaf); a node with two starts its own walk at
// itself. The second arriving walk writes union(left, right), the CPU
// refit's order. arrivals: clusters - 1, zero before the pass.
template <class Arrival>
RF_HDI void top_boxes_from_node(const TopBoxView& v, const uint32_t* top_parent, uint32_t* arrivals, uint32_t k) {
    const uint32_t left = v.top_refs[2 * k], right = v.top_refs[2 * k + 1];
    const bool top_left = is_top_reference(v, left), top_right = is_top_reference(v, right);
    if (top_left && top_right) return;  // its children's walks reach it
    uint32_t node = k, from;
    Box3f box;
    if (!top_left && !top_right) {
        box = box_union(reference_box(v.bottom, left), reference_box(v.bottom, right));
        v.top_boxes[k] = box;
        from = v.top_base + k;
        node = top_parent[k];
    } else {
        from = top_left ? right : left;
        box = reference_box(v.bottom, from);
    }
    while (node != kNoParent) {
        if (Arrival::arrive(&arrivals[node]) == 0) return;  // the sibling's walk goes on
        const uint32_t l = v.top_refs[2 * node], r = v.top_refs[2 * node + 1];
        const bool from_left = l == from;
        const Box3f other = top_child_box(v, from_left ? r : l);
        box = from_left ? box_union(box, other) : box_union(other, box);
        v.top_boxes[node] = box;
        from = v.top_base + node;
        node = top_parent[node];
    }
}

// One top level's record on the device, zero before the launch except
// level 0's root task. Level l's threads read record l (after a grid
// sync) and count their children into record l + 1, which one thread
// opens. Level l's nodes go to the level-node list from `base`, its large
// tasks' first.
struct TopQueueLevel {
    uint32_t small_head;  // the small queue's dequeue counter
    uint32_t small;       // tasks of at most kTopBlockTaskMin clusters
    uint32_t large;       // tasks of more
    uint32_t base;
    uint32_t fault;       // nonzero: this level or an earlier one overflowed
};

struct TopQueueCapacity {
    uint32_t small, large;  // queue entries
    uint32_t nodes;         // level-node list entries (the top nodes)
};

RF_HDI bool top_level_runs(const TopQueueLevel& l, const TopQueueCapacity& c) {
    return l.fault == 0 && l.small <= c.small && l.large <= c.large &&
           uint64_t{l.base} + l.small + l.large <= c.nodes;
}

// One thread of level l (block 0's first), before anything is enqueued.
// Returns top_level_runs(l, c).
RF_HDI bool open_next_top_level(const TopQueueLevel& l, TopQueueLevel* next, const TopQueueCapacity& c) {
    const bool runs = top_level_runs(l, c);
    next->base = runs ? l.base + l.small + l.large : l.base;
    next->fault = runs ? 0u : 1u;
    return runs;
}

}  // namespace rf::hlbvh2
