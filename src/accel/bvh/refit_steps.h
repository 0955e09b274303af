// Per-item steps of the bottom-up BVH refit, written once for both backends:
// the CPU refit (refit.cpp) runs them in TBB loops, the CUDA kernels
// (backend/cuda/bvh_refit.cu) one thread per item, and
// tests/bvh_refit_device_logic_test.cpp replays them in shuffled orders.
//
//  - parent_step(): inner node i records itself as its two children's
//    parent (siblings are adjacent in the canonical Bvh). Run once per tree.
//  - refit_from_leaf(): one leaf's work. Its box is recomputed from its
//    triangles, then it walks towards the root as in Karras 2012 sec. 4: an
//    arrival counter per inner node lets only the second child to arrive go
//    on, which computes the node's box from both children (left first, so the
//    result does not depend on which arrived last) and resets the counter,
//    so the counters are zero again after every pass and need no clearing.
//
// Boxes are combined with karras::box_union (std::min/max semantics), so a
// refit gives bit-identical boxes on both backends and in any order.
#pragma once

#include <cstdint>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::refit {

inline constexpr uint32_t kNoParent = karras::kNoParent;

// What a refit pass reads and writes; all arrays indexed by node.
struct RefitView {
    BvhNode* nodes;                // boxes rewritten, topology read
    const uint32_t* parents;       // per node, kNoParent for the root
    const uint32_t* prim_indices;  // the Bvh's leaf slots
    const Triangle* triangles;
    uint32_t* arrivals;            // per node, zero before and after a pass
};

// Node `index`'s children point back at it; the root gets kNoParent.
RF_HDI void parent_step(const BvhNode* nodes, uint32_t index, uint32_t* parents) {
    if (index == 0) parents[0] = kNoParent;
    const BvhNode& node = nodes[index];
    if (node.is_leaf()) return;
    parents[node.first] = index;
    parents[node.first + 1] = index;
}

// The triangle's box with std::min/max semantics (bit-identical on both backends).
RF_HDI Box3f triangle_box(const Triangle& t) {
    Box3f b;
    b.lo = t.v0;
    b.hi = t.v0;
    return karras::box_union(karras::box_union(b, Box3f{t.v1, t.v1}), Box3f{t.v2, t.v2});
}

// The box of `count` triangles referenced from prim_indices[first ...], in slot order.
RF_HDI Box3f leaf_box(const RefitView& view, uint32_t first, uint32_t count) {
    Box3f box = triangle_box(view.triangles[view.prim_indices[first]]);
    for (uint32_t s = first + 1; s < first + count; ++s) {
        box = karras::box_union(box, triangle_box(view.triangles[view.prim_indices[s]]));
    }
    return box;
}

// Leaf `leaf`'s box, then its walk towards the root. `Arrival` provides
// arrive(uint32_t*) -> count before (karras::AtomicArrival; tests inject others).
template <class Arrival>
RF_HDI void refit_from_leaf(const RefitView& view, uint32_t leaf) {
    const BvhNode& node = view.nodes[leaf];
    Box3f box = leaf_box(view, node.first, node.count);
    view.nodes[leaf].bounds = box;
    uint32_t from = leaf;
    uint32_t parent = view.parents[leaf];
    while (parent != kNoParent) {
        if (Arrival::arrive(&view.arrivals[parent]) == 0) return;
        view.arrivals[parent] = 0;  // both children are in: ready for the next pass
        const uint32_t left = view.nodes[parent].first;
        const bool from_left = from == left;
        const Box3f other = karras::load_shared_box(&view.nodes[from_left ? left + 1 : left].bounds);
        box = from_left ? karras::box_union(box, other) : karras::box_union(other, box);
        view.nodes[parent].bounds = box;
        from = parent;
        parent = view.parents[parent];
    }
}

}  // namespace rf::refit
