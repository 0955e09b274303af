// Top-down emission of the CWBVH (Ylitie, Karras and Laine 2017, section 3's
// wide tree encoded as in section 4) one level of wide nodes at a time, one
// thread per wide node, numbering nodes and triangles exactly as the CPU's
// depth-first build_cwbvh does (cwbvh_layout.cpp). Host and device code: the
// device (backend/cuda/layout_convert.cu) launches each pass once per level;
// the tests run the same steps in shuffled thread orders.
//
// The CPU emits wide nodes depth first (slot order), allocating a node's
// inner children contiguously when it is emitted and its leaf triangles
// after everything emitted before it. So, with "before(X)" the inner
// children and triangles of all wide nodes preceding X in that depth-first
// order, X's children start at 1 + before(X).inner and its triangles at
// before(X).triangles. The device gets the same numbers without a walk:
//  1. discover (per level, top down): X's slots (DP decisions, auction) and
//     its own counts; an exclusive scan of the inner counts over the level
//     places its inner children, in slot order, in the next level's queue;
//  2. totals (per level, bottom up): subtree(X) = own(X) + the children's;
//  3. emit (per level, top down): X's node and triangles at its numbers,
//     and for its k-th inner child: before = before(X) + own(X) + the
//     subtrees of children 0..k-1, index = 1 + before(X).inner + k.
#pragma once

#include <cstdint>

#include "accel/bvh/layout/cwbvh_collapse_steps.h"
#include "accel/bvh/layout/cwbvh_encode_steps.h"
#include "accel/bvh/layout/cwbvh_layout.h"

namespace rf::cwbvh {

// Error bits the emission reports (the host turns them into rf::Error).
inline constexpr uint32_t kErrorQuantize = 1u;

// Per wide node, in level order (level after level, each level in the order
// its parents enqueued it); the root is entry 0.
struct EmitView {
    const RefinedNode* nodes;
    const Choice* choices;
    const Triangle* triangles;
    uint32_t* wide_refined;  // the refined node the wide node covers
    uint32_t* slots;         // 8 per wide node: child_in_slot
    OwnCounts* own;          // its inner children and leaf triangles
    uint32_t* inner_count;   // own.inner, the scan's input
    uint32_t* first_child;   // scan output, then level-order index of its first inner child
    OwnCounts* subtree;      // own + all descendants'
    uint32_t* wide_index;    // its index in CwbvhBvh::nodes
    OwnCounts* before;       // what the depth-first order puts before it
    CwbvhNode* out_nodes;
    CwbvhTriangle* out_triangles;
    uint32_t* leaf_slots;    // one counter: leaf slots over all nodes
    uint32_t* error;         // one word of kError* bits
};

// Pass 1a for wide node i.
RF_HDI void discover(const EmitView& v, uint32_t i) {
    uint32_t child_in_slot[kWidth];
    assign_slots(v.nodes, v.choices, v.wide_refined[i], child_in_slot);
    for (int s = 0; s < kWidth; ++s) v.slots[size_t{i} * kWidth + s] = child_in_slot[s];
    const OwnCounts own = own_counts(v.nodes, v.choices, child_in_slot);
    v.own[i] = own;
    v.inner_count[i] = own.inner;
}

// Pass 1b, after the level's exclusive scan of inner_count into first_child:
// queues wide node i's inner children, in slot order, in the next level
// (which starts at next_level).
RF_HDI void enqueue_children(const EmitView& v, uint32_t i, uint32_t next_level) {
    const uint32_t first = next_level + v.first_child[i];
    v.first_child[i] = first;
    uint32_t r = 0;
    for (int s = 0; s < kWidth; ++s) {
        const uint32_t b = v.slots[size_t{i} * kWidth + s];
        if (b != kNoChild && is_wide_node(v.nodes, v.choices, b)) v.wide_refined[first + r++] = b;
    }
}

// Pass 2 for wide node i (its children's totals done: the level below).
RF_HDI void total(const EmitView& v, uint32_t i) {
    OwnCounts sum = v.own[i];
    for (uint32_t c = v.first_child[i]; c < v.first_child[i] + v.own[i].inner; ++c) {
        sum.inner += v.subtree[c].inner;
        sum.triangles += v.subtree[c].triangles;
    }
    v.subtree[i] = sum;
}

// Pass 3 for wide node i (its wide_index and before set by its parent; the
// root's are 0): writes its node and triangles, and its children's numbers.
RF_HDI void emit(const EmitView& v, uint32_t i) {
    uint32_t child_in_slot[kWidth];
    for (int s = 0; s < kWidth; ++s) child_in_slot[s] = v.slots[size_t{i} * kWidth + s];
    const OwnCounts before = v.before[i], own = v.own[i];
    const uint32_t base_child = 1u + before.inner;
    uint32_t inner[kWidth];
    int inner_count = 0;
    uint32_t leaf_slots = 0;
    const bool ok = encode_node(v.nodes, v.choices, v.triangles, child_in_slot, base_child, before.triangles,
                                v.out_nodes[v.wide_index[i]], v.out_triangles + before.triangles, inner,
                                inner_count, leaf_slots);
    OwnCounts next{before.inner + own.inner, before.triangles + own.triangles};
    for (uint32_t k = 0; k < own.inner; ++k) {
        const uint32_t c = v.first_child[i] + k;
        v.wide_index[c] = base_child + k;
        v.before[c] = next;
        next.inner += v.subtree[c].inner;
        next.triangles += v.subtree[c].triangles;
    }
#if defined(__CUDA_ARCH__)
    if (leaf_slots != 0) atomicAdd(v.leaf_slots, leaf_slots);
    if (!ok) atomicOr(v.error, kErrorQuantize);
#else
    *v.leaf_slots += leaf_slots;
    if (!ok) *v.error |= kErrorQuantize;
#endif
}

}  // namespace rf::cwbvh
