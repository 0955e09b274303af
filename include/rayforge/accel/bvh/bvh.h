// The canonical binary BVH: every BVH builder produces it, every traversal
// layout is converted from it, every quality metric is computed on it.
#pragma once

#include <cstdint>
#include <vector>

#include "rayforge/math/box.h"

namespace rf {

// 32 bytes. Inner node: count == 0, children at first_child and first_child + 1
// (siblings adjacent). Leaf: count > 0 primitives at prim_indices[first .. first+count).
struct BvhNode {
    Box3f bounds;
    uint32_t first = 0;   // first child (inner) or first primitive slot (leaf)
    uint32_t count = 0;   // primitives in the leaf; 0 for inner nodes
    RF_HDI bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(BvhNode) == 32, "BvhNode must stay 32 bytes");

// No root-to-leaf path has more inner nodes than this (every builder
// guarantees it), so traversals can use a fixed-size stack.
inline constexpr int kBvhMaxDepth = 64;

struct Bvh {
    std::vector<BvhNode> nodes;          // nodes[0] is the root
    std::vector<uint32_t> prim_indices;  // leaf slots -> triangle index

    [[nodiscard]] size_t leaf_count() const;
    [[nodiscard]] size_t memory_bytes() const {
        return nodes.size() * sizeof(BvhNode) + prim_indices.size() * sizeof(uint32_t);
    }
    // SAH cost with C_trav = C_int = 1, normalised by the root's area
    // (sum over inner nodes of A/A_root + sum over leaves of A/A_root * count).
    [[nodiscard]] double sah_cost(float traversal_cost = 1.0f, float intersection_cost = 1.0f) const;
    // Garanzha's recursive tree-quality cost (dissertation, formula 4.2):
    // leaf C = primitive count; inner C = nc + sum over children of
    // C(child) * area(child) / area(node). Tree quality is 1 / C(root).
    [[nodiscard]] double quality_cost(double node_cost = 2.0) const;
};

}  // namespace rf
