// The canonical emission of a Morton-family raw tree (morton_tree.h's
// RawTree: LBVH, HLBVH2, PLOC) as per-element steps, written once for both
// backends: the CUDA builders run them in three stages
// (backend/cuda/raw_tree_emit.cu), the CPU tests replay them in shuffled
// order against RawTree::emit. The result is RawTree::emit's, bit for bit,
// for every tree whose emitted height stays within kBvhMaxDepth (deeper
// trees go to the host, whose emitter rebuilds the offending subtrees).
//
//  1. scatter_parents(): one thread per node slot records itself as its
//     children's parent (slots a builder left unused hold kNoChild). For a
//     sparse numbering (HLBVH2 uses about a third of its slots), a prefix
//     sum of used_slot() then gives each used slot its place in the arrays
//     of node values (RawTreeView::dense).
//  2. finalize_from_leaf(): one thread per leaf walks up; as in Karras's
//     box pass, an arrival counter per node lets only the second child's
//     thread go on, and it computes the node's box, primitive count, SAH
//     cost, emitted size and height and the leaf collapse with combine(),
//     the function RawTree::finalize runs on the host (each product and sum
//     rounded once, so both backends get the same bits).
//  3. emit_node(): ONE launch, one thread per node slot: locate_node() sums
//     the node's depth-first position over its ancestors from the subtree
//     sizes, then emit_item() writes it and its leaf children. emit_item()
//     is also the per-level form (the CPU replay keeps it as the reference):
//     top down, one launch per level of the emitted tree (at
//     most kBvhMaxDepth + 1, known from the root's height), one thread per
//     item of the level: the item writes its output node (depth first,
//     siblings adjacent: a left child's children start 2 after its parent's,
//     a right child's after its left sibling's subtree, as RawTree::emit
//     places them) and queues its children with one atomicAdd; a leaf or a
//     collapsed node writes its primitives, left to right. Each emitted node
//     is visited once, and nothing below a collapsed node is queued.
//
// References: an inner node slot, or kLeafRef | the sorted position of a
// leaf run's first primitive. No std:: here: plain pointers, RF_HDI.
#pragma once

#include <cstdint>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "core/rounded_arithmetic.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf::raw_emit {

inline constexpr uint32_t kLeafRef = karras::kLeafRef;  // == morton::kLeafRef
inline constexpr uint32_t kNoParent = 0xffffffffu;      // the root's, and non-leaf positions'
inline constexpr uint32_t kNoChild = 0xffffffffu;       // a node slot the builder did not use
inline constexpr uint32_t kCollapsed = 1;               // == morton::kCollapsed: emitted as one leaf

RF_HDI bool is_leaf_ref(uint32_t ref) { return (ref & kLeafRef) != 0; }

// A node's finalized values, as morton::RawNode holds them.
struct NodeInfo {
    Box3f box;
    uint32_t count;     // primitives below
    float cost;         // SAH cost of the subtree as emitted (half areas, unnormalised)
    uint32_t out_size;  // output nodes of the subtree
    uint32_t height;    // (height << 1) | collapsed: inner nodes on the longest emitted path
};
static_assert(sizeof(NodeInfo) == 40);

RF_HDI uint32_t info_height(const NodeInfo& info) { return info.height >> 1; }
RF_HDI bool info_collapsed(const NodeInfo& info) { return (info.height & kCollapsed) != 0; }

struct Costs {
    float traversal;
    float intersection;
    uint32_t max_leaf_size;  // 1 .. 255
};

// The tree and the emitter's work arrays. Node slots [0, high_base) take
// their child pairs from `children`, slots [high_base, node_slots) from
// `high_children` (HLBVH2's top level lives in its own array).
struct RawTreeView {
    const uint32_t* children;       // 2 per node slot below high_base
    const uint32_t* high_children;  // 2 per node slot from high_base on (may be null when none)
    uint32_t high_base;
    uint32_t node_slots;
    uint32_t root;                  // reference
    uint32_t primitives;            // n
    const Box3f* boxes;             // per triangle when boxes_by_triangle, else per sorted position
    bool boxes_by_triangle;
    const uint32_t* order;          // sorted position -> triangle
    const uint8_t* leaf_runs;       // run size per leaf start, or null: every leaf one primitive
    uint32_t* node_parent;          // node_slots, kNoParent before scatter_parents
    uint32_t* leaf_parent;          // n, kNoParent before scatter_parents
    // Where a node slot's values live: dense[slot] (the exclusive prefix sum
    // of used_slot(), so a builder that leaves most slots unused, as HLBVH2
    // does, pays for the used ones only), or the slot itself when null.
    const uint32_t* dense;
    NodeInfo* info;                 // per value index, written by finalize_from_leaf
    uint32_t* arrivals;             // per value index, zero before finalize_from_leaf
    Costs costs;
};

RF_HDI uint32_t value_index(const RawTreeView& t, uint32_t node) { return t.dense != nullptr ? t.dense[node] : node; }
RF_HDI const NodeInfo& node_info(const RawTreeView& t, uint32_t node) { return t.info[value_index(t, node)]; }

RF_HDI const uint32_t* child_pair(const RawTreeView& t, uint32_t node) {
    return node < t.high_base ? t.children + 2 * static_cast<uint64_t>(node)
                              : t.high_children + 2 * static_cast<uint64_t>(node - t.high_base);
}

// x*y + y*z + z*x, each operation rounded once (morton::half_area's bits).
RF_HDI float half_area(const Box3f& b) {
    const float x = b.hi.x - b.lo.x, y = b.hi.y - b.lo.y, z = b.hi.z - b.lo.z;
    return add_rn(add_rn(mul_rn(x, y), mul_rn(y, z)), mul_rn(z, x));
}

RF_HDI uint32_t run_size(const RawTreeView& t, uint32_t first) {
    return t.leaf_runs != nullptr ? t.leaf_runs[first] : 1u;
}

RF_HDI Box3f position_box(const RawTreeView& t, uint32_t position) {
    return t.boxes[t.boxes_by_triangle ? t.order[position] : position];
}

// SAH cost of `count` primitives in one leaf of box `box` (unnormalised).
RF_HDI float leaf_cost(const Costs& costs, const Box3f& box, uint32_t count) {
    return mul_rn(mul_rn(costs.intersection, half_area(box)), static_cast<float>(count));
}

// The values of leaf run `first` (RawTree::info for a leaf reference).
RF_HDI NodeInfo leaf_info(const RawTreeView& t, uint32_t first) {
    const uint32_t n = run_size(t, first);
    Box3f box = position_box(t, first);
    for (uint32_t i = 1; i < n; ++i) box = karras::box_union(box, position_box(t, first + i));
    NodeInfo info;
    info.box = box;
    info.count = n;
    info.cost = leaf_cost(t.costs, box, n);
    info.out_size = 1;
    info.height = 0;
    return info;
}

// A node's values another thread wrote (L1 bypassed on the device, as
// karras::load_shared_box does).
RF_HDI NodeInfo load_shared_info(const NodeInfo* p) {
#if defined(__CUDA_ARCH__)
    NodeInfo info;
    info.box = karras::load_shared_box(&p->box);
    info.count = __ldcg(&p->count);
    info.cost = __ldcg(&p->cost);
    info.out_size = __ldcg(&p->out_size);
    info.height = __ldcg(&p->height);
    return info;
#else
    return *p;
#endif
}

// Step 1, for node slot `node`.
RF_HDI void scatter_parents(const RawTreeView& t, uint32_t node) {
    const uint32_t* pair = child_pair(t, node);
    for (int side = 0; side < 2; ++side) {
        const uint32_t child = pair[side];
        if (child == kNoChild) return;  // an unused slot has no children at all
        if (is_leaf_ref(child)) {
            t.leaf_parent[child & ~kLeafRef] = node;
        } else {
            t.node_parent[child] = node;
        }
    }
}

// After scatter_parents: whether node slot `node` is in the tree (1) or
// unused (0), the input of the prefix sum that gives RawTreeView::dense.
RF_HDI uint32_t used_slot(const RawTreeView& t, uint32_t node) {
    return t.node_parent[node] != kNoParent || t.root == node ? 1u : 0u;
}

// A node's values from its children's (RawTree::finalize runs this too).
RF_HDI NodeInfo combine(const Costs& costs, const NodeInfo& a, const NodeInfo& b) {
    NodeInfo node;
    node.box = karras::box_union(a.box, b.box);
    node.count = a.count + b.count;
    const float area = half_area(node.box);
    const float split_cost = add_rn(add_rn(mul_rn(costs.traversal, area), a.cost), b.cost);
    if (node.count <= costs.max_leaf_size) {
        const float as_leaf = mul_rn(mul_rn(costs.intersection, area), static_cast<float>(node.count));
        if (!(as_leaf > split_cost)) {
            node.cost = as_leaf;
            node.out_size = 1;
            node.height = kCollapsed;
            return node;
        }
    }
    node.cost = split_cost;
    node.out_size = 1 + a.out_size + b.out_size;
    const uint32_t ha = info_height(a), hb = info_height(b);
    node.height = (1 + (ha > hb ? ha : hb)) << 1;
    return node;
}

// Step 2, for sorted position `position` (threads of non-leaf positions
// return at once). `Arrival` as in karras::propagate_boxes_from_leaf.
template <class Arrival>
RF_HDI void finalize_from_leaf(const RawTreeView& t, uint32_t position) {
    uint32_t node = t.leaf_parent[position];
    if (node == kNoParent) return;  // not a leaf start, or the whole tree is one leaf
    uint32_t from = kLeafRef | position;
    NodeInfo info = leaf_info(t, position);
    while (node != kNoParent) {
        const uint32_t value = value_index(t, node);
        if (Arrival::arrive(&t.arrivals[value]) == 0) return;
        const uint32_t* pair = child_pair(t, node);
        const uint32_t left = pair[0], right = pair[1];
        const bool from_left = left == from;
        const uint32_t sibling = from_left ? right : left;
        const NodeInfo other =
            is_leaf_ref(sibling) ? leaf_info(t, sibling & ~kLeafRef) : load_shared_info(&t.info[value_index(t, sibling)]);
        info = from_left ? combine(t.costs, info, other) : combine(t.costs, other, info);
        t.info[value] = info;
        from = node;
        node = t.node_parent[node];
    }
}

// Whether the emission can run on the device: a tree whose emitted height
// exceeds kBvhMaxDepth needs the host's depth-limited rebuild.
RF_HDI bool fits_depth_limit(const NodeInfo& root) {
    return info_collapsed(root) || info_height(root) <= static_cast<uint32_t>(kBvhMaxDepth);
}

// One node of the top-down emission: the raw tree element (a node slot or a
// leaf reference), its output node, the first output node of its children
// and its first primitive slot.
struct EmitItem {
    uint32_t ref;
    uint32_t at;
    uint32_t child_base;
    uint32_t slot;
};

// The root's item: output node 0, its children from 1, primitives from 0.
RF_HDI EmitItem root_item(uint32_t root) { return EmitItem{root, 0u, 1u, 0u}; }

// Writes the primitives of leaf run `first` from prim_indices[*slot] on.
RF_HDI void write_leaf_prims(const RawTreeView& t, uint32_t first, uint32_t* prim_indices, uint32_t* slot) {
    const uint32_t n = run_size(t, first);
    for (uint32_t i = 0; i < n; ++i) prim_indices[(*slot)++] = t.order[first + i];
}

// The primitives below `node`, left to right, from prim_indices[slot] on: a
// walk without a stack (parent links lead back up), so a thread needs no
// local memory for it however the collapsed subtree is shaped.
RF_HDI void write_subtree_prims(const RawTreeView& t, uint32_t node, uint32_t* prim_indices, uint32_t slot) {
    constexpr uint32_t kFromAbove = 0xfffffffeu;  // neither a node nor a leaf reference
    uint32_t current = node, from = kFromAbove;
    for (;;) {
        const uint32_t* pair = child_pair(t, current);
        if (from == kFromAbove || from == pair[0]) {
            const uint32_t child = pair[from == kFromAbove ? 0 : 1];
            if (is_leaf_ref(child)) {
                write_leaf_prims(t, child & ~kLeafRef, prim_indices, &slot);
                from = child;  // as if back from it
            } else {
                current = child;
                from = kFromAbove;
            }
            continue;
        }
        if (current == node) return;  // back from the right child of the subtree's root
        from = current;
        current = t.node_parent[current];
    }
}

// Step 3 for one item of a level (the root's level first): writes its output
// node (and, for a leaf or a collapsed node, its primitives) and, for an
// inner node, appends its two children to the next level: the left child's
// children follow its sibling pair, the right child's follow the left
// child's subtree. `Counter::add(uint32_t* counter, uint32_t n)` returns the
// count before adding (an atomicAdd on the device); the order of a level's
// items does not matter, as every item carries its own positions.
template <class Counter>
RF_HDI void emit_item(const RawTreeView& t, const EmitItem& item, BvhNode* nodes, uint32_t* prim_indices,
                      EmitItem* next, uint32_t* next_count) {
    BvhNode& out = nodes[item.at];
    if (is_leaf_ref(item.ref)) {
        const uint32_t first = item.ref & ~kLeafRef;
        const NodeInfo info = leaf_info(t, first);
        out.bounds = info.box;
        out.first = item.slot;
        out.count = info.count;
        uint32_t slot = item.slot;
        write_leaf_prims(t, first, prim_indices, &slot);
        return;
    }
    const NodeInfo& info = node_info(t, item.ref);
    out.bounds = info.box;
    if (info_collapsed(info)) {
        out.first = item.slot;
        out.count = info.count;
        write_subtree_prims(t, item.ref, prim_indices, item.slot);
        return;
    }
    out.first = item.child_base;
    out.count = 0;
    const uint32_t* pair = child_pair(t, item.ref);
    const uint32_t left = pair[0], right = pair[1];
    const bool left_leaf = is_leaf_ref(left);
    const uint32_t left_count = left_leaf ? run_size(t, left & ~kLeafRef) : node_info(t, left).count;
    const uint32_t left_size = left_leaf ? 1u : node_info(t, left).out_size;
    const uint32_t at = Counter::add(next_count, 2u);
    next[at] = EmitItem{left, item.child_base, item.child_base + 2, item.slot};
    next[at + 1] = EmitItem{right, item.child_base + 1, item.child_base + 1 + left_size, item.slot + left_count};
}

// Levels of items step 3 runs (the root's level 0 included), from the root's
// values; fits_depth_limit(root) holds.
RF_HDI uint32_t emit_levels(const NodeInfo& root) { return info_collapsed(root) ? 1u : info_height(root) + 1u; }

// ---- Step 3 in one launch (what the device runs) ----------------------------
// emit_item's positions follow from subtree sizes alone: an edge to a left
// child adds 0 to the output node and 2 to the child base over the
// parent's child base, and nothing to the primitive slot; an edge to a
// right child adds 1, 1 + its left sibling's emitted size, and the left
// sibling's primitive count. So every node finds its item by summing the
// edges over its ancestors (as aila_laine::position_of does), and all nodes
// are emitted by one launch instead of one per level.
struct EdgeOffsets {
    uint32_t at;          // output node, over the parent's child base
    uint32_t child_base;  // the child's own child base, over the parent's
    uint32_t slot;        // first primitive slot, over the parent's
};

RF_HDI EdgeOffsets edge_offsets(const RawTreeView& t, uint32_t parent, uint32_t child) {
    const uint32_t* pair = child_pair(t, parent);
    const uint32_t left = pair[0];
    if (left == child) return EdgeOffsets{0u, 2u, 0u};
    if (is_leaf_ref(left)) return EdgeOffsets{1u, 2u, run_size(t, left & ~kLeafRef)};
    const NodeInfo& sibling = node_info(t, left);
    return EdgeOffsets{1u, 1u + sibling.out_size, sibling.count};
}

// Node slot `node`'s item, as the per-level emission would queue it. False
// for an unused slot and for a node below a collapsed one (that ancestor
// writes its primitives). Walks up to the root through node_parent.
RF_HDI bool locate_node(const RawTreeView& t, uint32_t node, EmitItem* item) {
    if (node == t.root) {
        *item = root_item(t.root);
        return true;
    }
    const uint32_t parent = t.node_parent[node];
    if (parent == kNoParent) return false;
    const EdgeOffsets own = edge_offsets(t, parent, node);
    uint32_t parent_base = 1u, slot = own.slot;  // the root's child base is 1
    for (uint32_t above = parent;; ) {
        if (info_collapsed(node_info(t, above))) return false;
        if (above == t.root) break;
        const uint32_t up = t.node_parent[above];
        const EdgeOffsets e = edge_offsets(t, up, above);
        parent_base += e.child_base;
        slot += e.slot;
        above = up;
    }
    *item = EmitItem{node, parent_base + own.at, parent_base + own.child_base, slot};
    return true;
}

// A thread's own two-item queue for emit_item.
struct LocalCounter {
    RF_HDI static uint32_t add(uint32_t* counter, uint32_t n) {
        const uint32_t before = *counter;
        *counter += n;
        return before;
    }
};

// Step 3 in one launch, for node slot `node` (the root's tree has a node
// root): emit_item for its own output node and for its leaf children,
// which have no thread of their own. Each output node is written once.
RF_HDI void emit_node(const RawTreeView& t, uint32_t node, BvhNode* nodes, uint32_t* prim_indices) {
    EmitItem item;
    if (!locate_node(t, node, &item)) return;
    EmitItem children[2];
    uint32_t queued = 0;
    emit_item<LocalCounter>(t, item, nodes, prim_indices, children, &queued);
    for (uint32_t k = 0; k < queued; ++k) {
        if (is_leaf_ref(children[k].ref)) emit_item<LocalCounter>(t, children[k], nodes, prim_indices, nullptr, nullptr);
    }
}

}  // namespace rf::raw_emit
