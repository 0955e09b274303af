// The per-node steps of the conversion to the node-pair layout of Aila and
// Laine 2009 ("Understanding the Efficiency of Ray Traversal on GPUs", HPG
// 2009, section 2: the compact "node pair" layout), shared by the CPU's
// depth-first conversion (aila_laine_layout.cpp) and the device's
// one-thread-per-node conversion (backend/cuda/layout_convert.cu).
//
// The device plan, which writes exactly the CPU's arrays without a
// depth-first walk:
//  1. parent links, one thread per inner node (parent_links_of);
//  2. subtree sizes bottom up, one thread per leaf walking up with an arrival
//     counter per inner node: only the second child to arrive sums both
//     children and goes on (propagate_sizes_from_leaf, as Karras 2012 does
//     for boxes);
//  3. positions: a node's depth-first (left before right) inner-node index
//     and its first float4 in the leaf lists are sums over its ancestors of
//     what the depth-first order puts before it: each ancestor itself, and
//     the left sibling's whole subtree wherever the path turns right
//     (position_of, O(depth) per thread, no global synchronisation);
//  4. one thread per node writes its node pair (write_node_pair) or its leaf
//     list (write_leaf_list) at its position.
#pragma once

#include <cstdint>

#include "accel/bvh/layout/aila_laine_layout.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::aila_laine {

inline constexpr uint32_t kNoParent = 0xFFFFFFFFu;

// float4s of a leaf list: three per triangle and the end marker.
RF_HDI uint32_t leaf_list_float4s(uint32_t count) { return count * uint32_t(kAilaLaineTriangleStride) + 1u; }

// What a subtree adds to the converted arrays.
struct SubtreeSize {
    uint32_t inner_nodes;   // node pairs
    uint32_t float4s;       // leaf-list float4s
    uint32_t leaves;
    uint32_t triangle_refs;
};

RF_HDI SubtreeSize leaf_size(const BvhNode& leaf) { return {0u, leaf_list_float4s(leaf.count), 1u, leaf.count}; }

RF_HDI SubtreeSize inner_size(const SubtreeSize& left, const SubtreeSize& right) {
    return {left.inner_nodes + right.inner_nodes + 1u, left.float4s + right.float4s, left.leaves + right.leaves,
            left.triangle_refs + right.triangle_refs};
}

// Stores `box` as child slot `side` (0 or 1) of `node`.
RF_HDI void set_child_box(AilaLaineNode& node, int side, const Box3f& box) {
    AilaLaineFloat4& xy = side == 0 ? node.xy0 : node.xy1;
    xy = {box.lo.x, box.hi.x, box.lo.y, box.hi.y};
    if (side == 0) {
        node.z.x = box.lo.z;
        node.z.y = box.hi.z;
    } else {
        node.z.z = box.lo.z;
        node.z.w = box.hi.z;
    }
}

// Writes the leaf's triangles (v0 with the triangle index's bits in w, v1,
// v2) and the end marker from `out` on. Indices must have been validated.
RF_HDI void write_leaf_list(const BvhNode& leaf, const uint32_t* prim_indices, const Triangle* triangles,
                            AilaLaineFloat4* out) {
    for (uint32_t slot = leaf.first; slot < leaf.first + leaf.count; ++slot) {
        const uint32_t prim = prim_indices[slot];
        const Triangle& tri = triangles[prim];
        *out++ = {tri.v0.x, tri.v0.y, tri.v0.z, bits_to_float(prim)};
        *out++ = {tri.v1.x, tri.v1.y, tri.v1.z, 0.0f};
        *out++ = {tri.v2.x, tri.v2.y, tri.v2.z, 0.0f};
    }
    *out = {bits_to_float(kAilaLaineLeafEndX), 0.0f, 0.0f, bits_to_float(kAilaLaineLeafEndW)};
}

// The node pair of canonical inner node `inner`, children at `left` and
// `left + 1`; links[c] as in AilaLaineNode. Padding is zero, as the CPU's
// value-initialised nodes.
RF_HDI AilaLaineNode make_node_pair(const BvhNode& left, const BvhNode& right, int32_t left_link,
                                    int32_t right_link) {
    AilaLaineNode node{};
    set_child_box(node, 0, left.bounds);
    set_child_box(node, 1, right.bounds);
    node.link[0] = left_link;
    node.link[1] = right_link;
    node.pad[0] = node.pad[1] = 0;
    return node;
}

// Step 1: the parents of inner node `inner`'s children.
RF_HDI void parent_links_of(const BvhNode* nodes, uint32_t inner, uint32_t* parent) {
    parent[nodes[inner].first] = inner;
    parent[nodes[inner].first + 1] = inner;
}

// A size written by another thread (another block on the device: read past L1).
RF_HDI SubtreeSize load_shared_size(const SubtreeSize* size) {
#if defined(__CUDA_ARCH__)
    const volatile SubtreeSize* v = size;
    return {v->inner_nodes, v->float4s, v->leaves, v->triangle_refs};
#else
    return *size;
#endif
}

// Step 2, one thread per canonical leaf `leaf`: writes its size and, as the
// second arrival at each ancestor, the ancestor's. `arrivals` (one zeroed
// counter per node) and `Arrival` as in karras::propagate_boxes_from_leaf
// (karras::AtomicArrival on the device; the tests inject others).
template <class Arrival>
RF_HDI void propagate_sizes_from_leaf(const BvhNode* nodes, const uint32_t* parent, uint32_t leaf,
                                      SubtreeSize* size, uint32_t* arrivals) {
    size[leaf] = leaf_size(nodes[leaf]);
    uint32_t node = parent[leaf];
    while (node != kNoParent) {
        if (Arrival::arrive(&arrivals[node]) == 0) return;
        const uint32_t left = nodes[node].first;
        size[node] = inner_size(load_shared_size(&size[left]), load_shared_size(&size[left + 1]));
        node = parent[node];
    }
}

// Where canonical node `node` lands in the depth-first order.
struct Position {
    uint32_t inner_index;    // inner node: its node pair; leaf: node pairs before it
    uint32_t float4_offset;  // first float4 of its leaf lists
};

// Step 3: sums over the ancestors (the root is node 0, parent kNoParent).
RF_HDI Position position_of(const BvhNode* nodes, const uint32_t* parent, const SubtreeSize* size, uint32_t node) {
    Position p{0u, 0u};
    for (uint32_t child = node; child != 0;) {
        const uint32_t up = parent[child];
        const uint32_t left = nodes[up].first;
        p.inner_index += 1u;  // the ancestor's own pair comes first
        if (child != left) {  // a right child: the left sibling's subtree comes before it
            p.inner_index += size[left].inner_nodes;
            p.float4_offset += size[left].float4s;
        }
        child = up;
    }
    return p;
}

// Step 4 for inner node `inner` at position `at`: its pair with the links
// to its children (inner: their pair index; leaf: ~their first float4).
RF_HDI AilaLaineNode node_pair_at(const BvhNode* nodes, const SubtreeSize* size, uint32_t inner, Position at) {
    const uint32_t left = nodes[inner].first;
    const BvhNode& l = nodes[left];
    const BvhNode& r = nodes[left + 1];
    const uint32_t right_index = at.inner_index + 1u + size[left].inner_nodes;
    const uint32_t right_offset = at.float4_offset + size[left].float4s;
    const int32_t left_link = l.is_leaf() ? ~int32_t(at.float4_offset) : int32_t(at.inner_index + 1u);
    const int32_t right_link = r.is_leaf() ? ~int32_t(right_offset) : int32_t(right_index);
    return make_node_pair(l, r, left_link, right_link);
}

}  // namespace rf::aila_laine
