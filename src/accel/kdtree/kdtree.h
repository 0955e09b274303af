// The SAH kd-tree of Zlatuška 2009 (after Wald and Havran 2006):
// compact 8-byte nodes in the classic layout (split position, axis or leaf
// flag, child or primitive offset), children stored next to each other.
#pragma once

#include <cstdint>
#include <cstring>
#include <vector>

#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf {

// No root-to-leaf path has more inner nodes than this: builders cap the depth
// below it, so traversals use fixed-size stacks and 64-bit per-depth masks.
inline constexpr int kKdMaxDepth = 60;

// 8 bytes. word1's two low bits hold the split axis (0, 1, 2) or 3 for a leaf;
// its 30 high bits the index of the first child (inner: children at that index
// and the next) or the first primitive slot (leaf). word0 is the split
// position's bits (inner) or the leaf's primitive count.
struct KdNode {
    uint32_t word0 = 0;
    uint32_t word1 = 3;

    static constexpr uint32_t kMaxIndex = (1u << 30) - 1;  // largest child / slot index

    RF_HDI bool is_leaf() const { return (word1 & 3u) == 3u; }
    RF_HDI int axis() const { return static_cast<int>(word1 & 3u); }
    RF_HDI float split() const { return bits_to_float(word0); }
    RF_HDI uint32_t first_child() const { return word1 >> 2; }
    RF_HDI uint32_t prim_count() const { return word0; }
    RF_HDI uint32_t prim_offset() const { return word1 >> 2; }

    static KdNode inner(int axis, float split, uint32_t first_child) {
        KdNode n;
        std::memcpy(&n.word0, &split, sizeof split);
        n.word1 = (first_child << 2) | static_cast<uint32_t>(axis);
        return n;
    }
    static KdNode leaf(uint32_t prim_offset, uint32_t prim_count) {
        KdNode n;
        n.word0 = prim_count;
        n.word1 = (prim_offset << 2) | 3u;
        return n;
    }
};
static_assert(sizeof(KdNode) == 8, "KdNode must stay 8 bytes");

// A leaf with its cell (the node's box, derived from the splits above it).
struct KdLeafInfo {
    uint32_t node = 0;
    int depth = 0;
    Box3f cell;
};

struct KdTree {
    std::vector<KdNode> nodes;           // nodes[0] is the root; empty for an empty tree
    std::vector<uint32_t> prim_indices;  // leaf slots -> triangle index
    Box3f bounds;                        // the root cell
    int max_depth = 0;                   // the depth limit the build used (<= kKdMaxDepth)

    [[nodiscard]] size_t memory_bytes() const {
        return nodes.size() * sizeof(KdNode) + prim_indices.size() * sizeof(uint32_t);
    }
    [[nodiscard]] size_t leaf_count() const;
    [[nodiscard]] size_t empty_leaf_count() const;
    [[nodiscard]] int depth() const;  // inner nodes on the longest root-to-leaf path
    // Every leaf with its cell, in depth-first order.
    [[nodiscard]] std::vector<KdLeafInfo> leaves() const;
    // SAH cost normalised by the root cell's area: sum over inner nodes of
    // C_trav * A/A_root plus sum over leaves of C_int * count * A/A_root.
    [[nodiscard]] double sah_cost(float traversal_cost = 1.0f, float intersection_cost = 1.0f) const;
};

}  // namespace rf
