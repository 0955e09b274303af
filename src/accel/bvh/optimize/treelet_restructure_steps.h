// Per-node steps of treelet restructuring (Karras and Aila 2013, "Fast
// Parallel Construction of High-Quality Bounding Volume Hierarchies", HPG
// 2013), written once for both backends: the CPU pass
// (treelet_restructure.cpp) runs them in TBB loops, the CUDA pass
// (backend/cuda/treelet_restructure.cu) one thread per item, and the tests
// replay them in shuffled orders.
//
//  - init_node(): the working tree from the canonical Bvh: a child pair and a
//    parent per node, boxes and primitive counts (leaves never change: the
//    canonical leaves are the treelets' atoms).
//  - restructure_from_leaf(): one leaf's work in a round. As in the paper's
//    §5 (and Karras 2012's box pass) the leaf walks towards the root; an
//    arrival counter per node lets only the second child to arrive go on, so
//    a node is processed once both of its subtrees are final. A node with at
//    least gamma primitives below is a treelet root (§5: small subtrees gain
//    little): its treelet is formed (§4.1: start from the root's two
//    children, expand the treelet leaf of largest surface area until there are
//    n leaves), its optimal topology found by dynamic programming over the
//    leaf subsets (§4.2-4.3, Algorithm 2: subset areas, then C_opt of each
//    subset from its partitions, enumerated with p = (p - 1) & s), and the
//    treelet's n - 1 internal nodes relinked to that topology. Any
//    other node only gets its cost.
//  - raw_children(): the final topology as a raw tree (raw_tree_emit_steps.h:
//    node slots = node indices, leaves = kLeafRef | first slot), which the
//    Morton builders' emitter collapses and lays out in canonical order.
//
// The cost of a subset s is the paper's formula 2 with the leaf-size limit:
//   C(s) = min(C_trav A(s) + C(p) + C(s \ p), C_int A(s) N(s) if N(s) <= max leaf size),
// half areas, raw_emit::combine's operations in its order (each product and
// sum rounded once), so the emitter's collapse agrees and both backends get
// the same bits. Ties keep the first partition found, so the result is a
// function of the input tree alone, whatever the schedule.
//
// Differences from the paper: the input's leaves (up to the leaf-size limit)
// stay whole, where the paper starts from one triangle per leaf; one thread
// per treelet where the paper uses a warp.
#pragma once

#include <cstdint>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/raw_tree_emit_steps.h"
#include "core/rounded_arithmetic.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::treelet {

inline constexpr int kMaxLeaves = 7;  // the paper's n = 7
inline constexpr int kMinLeaves = 3;  // fewer leaves have one topology only
inline constexpr uint32_t kMaxSubsets = 1u << kMaxLeaves;
inline constexpr uint32_t kNoParent = karras::kNoParent;

// The working tree; every array is indexed by canonical node index.
struct TreeView {
    const BvhNode* nodes;  // the input: which nodes are leaves, and their boxes and counts
    uint32_t* children;    // 2 per node; inner nodes only
    uint32_t* parents;     // kNoParent for the root
    Box3f* boxes;
    uint32_t* counts;      // primitives below
    float* costs;          // SAH cost of the subtree (half areas, unnormalised), this round's
    uint32_t* arrivals;    // zero before and after a round
    raw_emit::Costs sah;
    uint32_t gamma;        // smallest subtree (in primitives) restructured this round
    int treelet_leaves;    // n, kMinLeaves .. kMaxLeaves
};

// Loads of values another thread wrote (L1 bypassed on the device, as
// karras::load_shared_box does).
RF_HDI uint32_t load_shared(const uint32_t* p) {
#if defined(__CUDA_ARCH__)
    return __ldcg(p);
#else
    return *p;
#endif
}
RF_HDI float load_shared(const float* p) {
#if defined(__CUDA_ARCH__)
    return __ldcg(p);
#else
    return *p;
#endif
}

RF_HDI bool is_leaf(const TreeView& t, uint32_t node) { return t.nodes[node].is_leaf(); }

// Node `index` of the canonical input into the working tree.
RF_HDI void init_node(const TreeView& t, uint32_t index) {
    const BvhNode& node = t.nodes[index];
    if (index == 0) t.parents[0] = kNoParent;
    t.boxes[index] = node.bounds;
    t.counts[index] = node.count;  // inner nodes: set by their round
    t.arrivals[index] = 0;
    if (node.is_leaf()) return;
    t.children[2 * index] = node.first;
    t.children[2 * index + 1] = node.first + 1;
    t.parents[node.first] = index;
    t.parents[node.first + 1] = index;
}

// C_opt of a subset from its best partition's children costs: formula 2,
// raw_emit::combine's operations in its order.
RF_HDI float split_cost(const raw_emit::Costs& sah, float area, float left, float right) {
    return add_rn(add_rn(mul_rn(sah.traversal, area), left), right);
}
RF_HDI float with_leaf_option(const raw_emit::Costs& sah, float area, uint32_t count, float split) {
    if (count > sah.max_leaf_size) return split;
    const float as_leaf = mul_rn(mul_rn(sah.intersection, area), static_cast<float>(count));
    return as_leaf > split ? split : as_leaf;
}

// The treelet of root `root` (§4.1): its leaves and internal nodes
// (internal[0] is the root).
struct Treelet {
    uint32_t leaves[kMaxLeaves];
    uint32_t internal[kMaxLeaves - 1];
    int leaf_count;
};

// Grows the treelet from the root's children, each time replacing the
// treelet leaf of largest surface area by its two children (the first such
// leaf on ties); canonical leaves cannot grow. Stops at n leaves or when no
// treelet leaf can grow.
RF_HDI Treelet form_treelet(const TreeView& t, uint32_t root) {
    Treelet tr;
    tr.internal[0] = root;
    tr.leaves[0] = load_shared(&t.children[2 * root]);
    tr.leaves[1] = load_shared(&t.children[2 * root + 1]);
    tr.leaf_count = 2;
    while (tr.leaf_count < t.treelet_leaves) {
        int largest = -1;
        float largest_area = -1.0f;
        for (int i = 0; i < tr.leaf_count; ++i) {
            if (is_leaf(t, tr.leaves[i])) continue;
            const float area = raw_emit::half_area(karras::load_shared_box(&t.boxes[tr.leaves[i]]));
            if (area > largest_area) {
                largest_area = area;
                largest = i;
            }
        }
        if (largest < 0) break;
        const uint32_t grown = tr.leaves[largest];
        tr.internal[tr.leaf_count - 1] = grown;
        tr.leaves[largest] = load_shared(&t.children[2 * grown]);
        tr.leaves[tr.leaf_count++] = load_shared(&t.children[2 * grown + 1]);
    }
    return tr;
}

// The optimal topology of a treelet's leaves (§4.2-4.3): for every subset s
// of the leaves (bit i = leaf i), cost[s] = C_opt(s) and partition[s] = the
// leaves of s's left child in the optimum.
struct TreeletLeaves {
    Box3f boxes[kMaxLeaves];
    float costs[kMaxLeaves];
    uint32_t counts[kMaxLeaves];
    int count;
};
struct OptimalTopology {
    float cost[kMaxSubsets];
    uint8_t partition[kMaxSubsets];
};

RF_HDI Box3f subset_box(const TreeletLeaves& leaves, uint32_t subset) {
    Box3f box;
    bool first = true;
    for (int i = 0; i < leaves.count; ++i) {
        if ((subset >> i & 1u) == 0) continue;
        box = first ? leaves.boxes[i] : karras::box_union(box, leaves.boxes[i]);
        first = false;
    }
    return box;
}
RF_HDI uint32_t subset_count(const TreeletLeaves& leaves, uint32_t subset) {
    uint32_t count = 0;
    for (int i = 0; i < leaves.count; ++i) count += (subset >> i & 1u) != 0 ? leaves.counts[i] : 0u;
    return count;
}

// Algorithm 2 of the paper. Subsets are solved in increasing numeric order,
// which puts every proper subset of s before s. Each partition {p, s \ p}
// is tried once: p holds s's lowest leaf, the rest of p is enumerated over
// the subsets of s's other leaves with q = (q - 1) & rest.
RF_HDI void solve_topology(const raw_emit::Costs& sah, const TreeletLeaves& leaves, OptimalTopology& out) {
    const uint32_t full = (1u << leaves.count) - 1u;
    for (uint32_t s = 1; s <= full; ++s) {
        if ((s & (s - 1)) == 0) {  // one leaf
            int i = 0;
            while ((s >> i) != 1u) ++i;
            out.cost[s] = leaves.costs[i];
            out.partition[s] = 0;
            continue;
        }
        const float area = raw_emit::half_area(subset_box(leaves, s));
        const uint32_t lowest = s & (~s + 1u), rest = s ^ lowest;
        float best = 0.0f;
        uint32_t best_left = 0;
        for (uint32_t q = (rest - 1u) & rest;; q = (q - 1u) & rest) {
            const uint32_t left = lowest | q;
            const float cost = split_cost(sah, area, out.cost[left], out.cost[s ^ left]);
            if (best_left == 0 || cost < best) {
                best = cost;
                best_left = left;
            }
            if (q == 0) break;
        }
        out.cost[s] = with_leaf_option(sah, area, subset_count(leaves, s), best);
        out.partition[s] = static_cast<uint8_t>(best_left);
    }
}

// Relinks the treelet's internal nodes to the optimal topology: the
// root keeps its place, the other internal nodes are reused in the order
// they joined the treelet; each gets its subset's box, count and C_opt.
RF_HDI void reconstruct(const TreeView& t, const Treelet& tr, const TreeletLeaves& leaves,
                        const OptimalTopology& topology) {
    struct Pending {
        uint32_t subset;
        uint32_t node;
    };
    Pending stack[kMaxLeaves];
    int top = 0, next_internal = 1;
    stack[top++] = {(1u << tr.leaf_count) - 1u, tr.internal[0]};
    while (top > 0) {
        const Pending item = stack[--top];
        t.boxes[item.node] = subset_box(leaves, item.subset);
        t.counts[item.node] = subset_count(leaves, item.subset);
        t.costs[item.node] = topology.cost[item.subset];
        const uint32_t left = topology.partition[item.subset];
        for (int side = 0; side < 2; ++side) {
            const uint32_t part = side == 0 ? left : item.subset ^ left;
            uint32_t child;
            if ((part & (part - 1)) == 0) {
                int i = 0;
                while ((part >> i) != 1u) ++i;
                child = tr.leaves[i];
            } else {
                child = tr.internal[next_internal++];
                stack[top++] = {part, child};
            }
            t.children[2 * item.node + side] = child;
            t.parents[child] = item.node;
        }
    }
}

// Forms, solves and relinks the treelet of `root`; returns false (nothing
// changed) when it has fewer than kMinLeaves leaves.
RF_HDI bool restructure_treelet(const TreeView& t, uint32_t root) {
    const Treelet tr = form_treelet(t, root);
    if (tr.leaf_count < kMinLeaves) return false;
    TreeletLeaves leaves;
    leaves.count = tr.leaf_count;
    for (int i = 0; i < tr.leaf_count; ++i) {
        const uint32_t leaf = tr.leaves[i];
        leaves.boxes[i] = karras::load_shared_box(&t.boxes[leaf]);
        leaves.costs[i] = load_shared(&t.costs[leaf]);
        leaves.counts[i] = load_shared(&t.counts[leaf]);
    }
    OptimalTopology topology;
    solve_topology(t.sah, leaves, topology);
    reconstruct(t, tr, leaves, topology);
    return true;
}

// A node whose two subtrees are final: restructured when it roots at least
// gamma primitives, else only its count and cost (its box never changes:
// the primitives below it stay the same).
RF_HDI void process_node(const TreeView& t, uint32_t node) {
    const uint32_t left = load_shared(&t.children[2 * node]), right = load_shared(&t.children[2 * node + 1]);
    const uint32_t count = load_shared(&t.counts[left]) + load_shared(&t.counts[right]);
    if (count >= t.gamma && restructure_treelet(t, node)) return;
    const float area = raw_emit::half_area(karras::load_shared_box(&t.boxes[node]));
    const float split = split_cost(t.sah, area, load_shared(&t.costs[left]), load_shared(&t.costs[right]));
    t.counts[node] = count;
    t.costs[node] = with_leaf_option(t.sah, area, count, split);
}

// One round's work of canonical leaf `leaf`. `Arrival` provides
// arrive(uint32_t*) -> count before (karras::AtomicArrival; tests inject
// others). A treelet root's parent never changes in its own round (only
// treelets above it are relinked, after it), so the walk can read it after
// the restructuring.
template <class Arrival>
RF_HDI void restructure_from_leaf(const TreeView& t, uint32_t leaf) {
    t.costs[leaf] = raw_emit::leaf_cost(t.sah, t.boxes[leaf], t.counts[leaf]);
    uint32_t node = t.parents[leaf];
    while (node != kNoParent) {
        if (Arrival::arrive(&t.arrivals[node]) == 0) return;
        t.arrivals[node] = 0;  // both children are in: ready for the next round
        process_node(t, node);
        node = load_shared(&t.parents[node]);
    }
}

// The final topology as a raw tree for raw_emit / morton::RawTree: node
// `index`'s child pair as references (an inner node's index, or kLeafRef |
// a canonical leaf's first slot); raw_emit::kNoChild for leaves' slots.
RF_HDI void raw_children(const TreeView& t, uint32_t index, uint32_t* raw) {
    if (is_leaf(t, index)) {
        raw[2 * index] = raw[2 * index + 1] = raw_emit::kNoChild;
        return;
    }
    for (int side = 0; side < 2; ++side) {
        const uint32_t child = t.children[2 * index + side];
        raw[2 * index + side] = is_leaf(t, child) ? (raw_emit::kLeafRef | t.nodes[child].first) : child;
    }
}

// The box of leaf slot `slot` of canonical leaf `node` for the emitter: its
// triangle's box clipped to the leaf's (the triangle's box itself for whole
// references, whose leaf box holds it; a clipped piece inside it for the
// split references of SBVH and GridBvhSplit, so their leaves keep their
// boxes), or the leaf's box where the two do not overlap.
RF_HDI void leaf_slot_boxes(const BvhNode& node, const uint32_t* prim_indices, const Triangle* triangles,
                            Box3f* boxes) {
    const Box3f& leaf = node.bounds;
    for (uint32_t s = node.first; s < node.first + node.count; ++s) {
        const Triangle& tri = triangles[prim_indices[s]];
        const Box3f whole = karras::box_union(karras::box_union(Box3f{tri.v0, tri.v0}, Box3f{tri.v1, tri.v1}),
                                              Box3f{tri.v2, tri.v2});
        Box3f clipped;
        clipped.lo = Vec3f(whole.lo.x > leaf.lo.x ? whole.lo.x : leaf.lo.x, whole.lo.y > leaf.lo.y ? whole.lo.y : leaf.lo.y,
                           whole.lo.z > leaf.lo.z ? whole.lo.z : leaf.lo.z);
        clipped.hi = Vec3f(whole.hi.x < leaf.hi.x ? whole.hi.x : leaf.hi.x, whole.hi.y < leaf.hi.y ? whole.hi.y : leaf.hi.y,
                           whole.hi.z < leaf.hi.z ? whole.hi.z : leaf.hi.z);
        const bool overlap = clipped.lo.x <= clipped.hi.x && clipped.lo.y <= clipped.hi.y && clipped.lo.z <= clipped.hi.z;
        boxes[s] = overlap ? clipped : leaf;
    }
}

}  // namespace rf::treelet
