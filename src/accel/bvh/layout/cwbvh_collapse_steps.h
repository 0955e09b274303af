// The per-node steps of the CWBVH collapse of Ylitie, Karras and Laine 2017
// ("Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide
// BVHs", HPG 2017), section 3: the cost-optimal dynamic programme over the
// binary BVH refined to single-triangle leaves, and the choice of a wide
// node's slots from its decisions. Shared by the CPU's build_cwbvh
// (cwbvh_layout.cpp, nodes solved in reverse index order) and the device
// (backend/cuda/layout_convert.cu: one thread per refined leaf walking up,
// the second child to arrive at a node solving it, as Karras 2012 does for
// boxes).
//
// Float costs are computed with operations that are never contracted into
// fused multiply-adds (mul_rn, add_rn: __fmul_rn/__fadd_rn on the device; the
// host compiles with -ffp-contract=off), so both sides take the same
// decisions bit for bit.
#pragma once

#include <cstdint>

#include "core/rounded_arithmetic.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cwbvh {

inline constexpr int kWidth = 8;            // = kCwbvhWidth
inline constexpr uint32_t kMaxLeafTriangles = 3;  // = kCwbvhMaxLeafTriangles
inline constexpr uint32_t kNoParent = 0xFFFFFFFFu;

// Relative costs of the paper (section 3): one node fetch and box test of
// its children, one triangle test.
inline constexpr float kNodeCost = 1.0f;
inline constexpr float kTriangleCost = 0.3f;

// A node of the canonical BVH with its leaves split down to single
// triangles, the input the paper's DP expects. Children of an inner node sit
// at `left` and `left + 1`, always after their parent.
struct RefinedNode {
    Box3f box;
    uint32_t left = 0;       // inner: first child
    uint32_t prim = 0;       // leaf: triangle index
    uint32_t triangles = 0;  // in the subtree
    uint32_t leaf = 0;       // 1 for a single-triangle leaf
};

// DP decisions of a node. split[0]: as one slot, wide node (bit 0) or leaf,
// and as a wide node the slots its left child gets (bits 1..4).
// split[i - 1], i >= 2: left | right << 4 slots, or 0 = one slot.
struct Choice {
    uint8_t split[kWidth];
};


// A cost row entry another thread wrote (another block on the device: read
// from L2, past a possibly stale L1 line).
RF_HDI float load_cost(const float* at) {
#if defined(__CUDA_ARCH__)
    return __ldcg(at);
#else
    return *at;
#endif
}

RF_HDI bool finite(float x) { return (float_to_bits(x) & 0x7F800000u) != 0x7F800000u; }

// Box3f::surface_area, operation for operation, without contraction.
RF_HDI float surface_area(const Box3f& b) {
    if (b.is_empty()) return 0.0f;
    const Vec3f e = b.extent();
    return mul_rn(2.0f, add_rn(add_rn(mul_rn(e.x, e.y), mul_rn(e.y, e.z)), mul_rn(e.z, e.x)));
}

// Added to every area: keeps zero-area subtrees from tying, so that fewer
// nodes and tests win.
RF_HDI float area_bias(const Box3f& root_box) {
    const float root_area = surface_area(root_box);
    return root_area > 0.0f && finite(root_area) ? mul_rn(root_area, 1e-7f) : 1.0f;
}

RF_HDI float node_area(const RefinedNode& n, float bias) {
    const float a = surface_area(n.box);
    return add_rn(finite(a) ? a : 3.40282347e+38f, bias);
}

// cost[n * kWidth + i - 1]: least cost of covering subtree n with at most i
// slots of its parent, each slot a leaf of at most three triangles or a wide
// node. Solves node n from its children's rows (already solved).
RF_HDI void solve_node(const RefinedNode* nodes, uint32_t n, float bias, float* cost, Choice* choices) {
    const float kInf = bits_to_float(0x7F800000u);
    const RefinedNode& node = nodes[n];
    float* c = cost + size_t{n} * kWidth;
    Choice& choice = choices[n];
    const float area = node_area(node, bias);
    if (node.leaf) {
        for (int i = 0; i < kWidth; ++i) {
            c[i] = mul_rn(area, kTriangleCost);
            choice.split[i] = 0;
        }
        return;
    }
    const float* left = cost + size_t{node.left} * kWidth;
    const float* right = cost + (size_t{node.left} + 1) * kWidth;
    // dist[j - 1]: both children sharing at most j slots, the left one
    // getting dist_k[j - 1].
    float dist[kWidth];
    int dist_k[kWidth];
    dist[0] = kInf;
    dist_k[0] = 0;
    for (int j = 2; j <= kWidth; ++j) {
        dist[j - 1] = kInf;
        dist_k[j - 1] = 1;
        for (int k = 1; k < j; ++k) {
            const float s = add_rn(load_cost(left + k - 1), load_cost(right + j - k - 1));
            if (s < dist[j - 1]) {
                dist[j - 1] = s;
                dist_k[j - 1] = k;
            }
        }
    }
    const float as_node = add_rn(mul_rn(area, kNodeCost), dist[kWidth - 1]);
    const float as_leaf =
        node.triangles <= kMaxLeafTriangles ? mul_rn(mul_rn(area, kTriangleCost), float(node.triangles)) : kInf;
    // A node over more triangles than a leaf holds is inner even when its
    // costs overflow to infinity (coordinates near 1e19): a leaf could not hold it.
    const bool is_inner = as_node < as_leaf || node.triangles > kMaxLeafTriangles;
    c[0] = is_inner ? as_node : as_leaf;
    choice.split[0] = uint8_t((is_inner ? 1u : 0u) | (unsigned(dist_k[kWidth - 1]) << 1));
    uint8_t split = 0;  // one slot
    for (int i = 2; i <= kWidth; ++i) {
        if (dist[i - 1] < c[i - 2]) {
            c[i - 1] = dist[i - 1];
            split = uint8_t(dist_k[i - 1] | ((i - dist_k[i - 1]) << 4));
        } else {
            c[i - 1] = c[i - 2];
        }
        choice.split[i - 1] = split;
    }
}

// Parents of inner node `inner`'s children (the device's first pass).
RF_HDI void parent_links_of(const RefinedNode* nodes, uint32_t inner, uint32_t* parent) {
    parent[nodes[inner].left] = inner;
    parent[nodes[inner].left + 1] = inner;
}

// A triangle count another thread wrote (another block on the device).
RF_HDI uint32_t load_triangle_count(const RefinedNode* node) {
#if defined(__CUDA_ARCH__)
    return __ldcg(&node->triangles);
#else
    return node->triangles;
#endif
}

// The device's DP, one thread per refined leaf: solves the leaf, then each
// ancestor where it is the second child to arrive, setting the ancestor's
// triangle count (the sum of its children's: the device's refinement leaves
// canonical inner nodes at 0) just before solving it. `arrivals`: one zeroed
// counter per node; `Arrival` as in karras::propagate_boxes_from_leaf.
template <class Arrival>
RF_HDI void count_and_solve_from_leaf(RefinedNode* nodes, const uint32_t* parent, uint32_t leaf, float bias,
                                      float* cost, Choice* choices, uint32_t* arrivals) {
    solve_node(nodes, leaf, bias, cost, choices);
    for (uint32_t node = parent[leaf]; node != kNoParent; node = parent[node]) {
        if (Arrival::arrive(&arrivals[node]) == 0) return;
        const uint32_t left = nodes[node].left;
        nodes[node].triangles = load_triangle_count(&nodes[left]) + load_triangle_count(&nodes[left + 1]);
        solve_node(nodes, node, bias, cost, choices);
    }
}

// Refined node b covered by one slot of its parent becomes a wide node
// (else a leaf of at most three triangles).
RF_HDI bool is_wide_node(const RefinedNode* nodes, const Choice* choices, uint32_t b) {
    return !nodes[b].leaf && (choices[b].split[0] & 1u) != 0;
}

// The slots of refined inner node b as a wide node, left to right; returns
// their number (at most kWidth). The paper's recursion on the decisions,
// with an explicit stack (right part pushed first).
RF_HDI int node_slots(const RefinedNode* nodes, const Choice* choices, uint32_t b, uint32_t (&slots)[kWidth]) {
    struct Part {
        uint32_t node;
        int slots;
    };
    Part stack[2 * kWidth];
    int top = 0;
    const int k = choices[b].split[0] >> 1;
    stack[top++] = {nodes[b].left + 1, kWidth - k};
    stack[top++] = {nodes[b].left, k};
    int used = 0;
    while (top > 0) {
        const Part p = stack[--top];
        const uint8_t s = p.slots >= 2 ? choices[p.node].split[p.slots - 1] : uint8_t(0);
        if (s == 0) {
            slots[used++] = p.node;
            continue;
        }
        stack[top++] = {nodes[p.node].left + 1, s >> 4};
        stack[top++] = {nodes[p.node].left, s & 15};
    }
    return used;
}

}  // namespace rf::cwbvh
