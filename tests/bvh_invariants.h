// The invariants of the canonical BVH (rayforge/accel/bvh/bvh.h), checked in
// one place so that every builder's, optimizer's and updater's tests hold
// their trees to the same rules: depth-first order with siblings adjacent,
// no unreachable node, a full binary tree, every leaf slot used once, leaves
// within the size limit, depth within kBvhMaxDepth, every triangle referenced,
// and every box the exact union of what lies under it; relaxed (Refs) only
// where a builder references triangles more than once or clips them.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::test {

// Bit-exact (up to -0 == +0): builders and refits compute unions with min and
// max, which round nothing, so a box off by an ulp is a bug.
inline bool same_box(const Box3f& a, const Box3f& b) { return a.lo == b.lo && a.hi == b.hi; }

// The same tree bit for bit (determinism across thread counts and options).
inline bool identical(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() && a.prim_indices == b.prim_indices &&
           std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode)) == 0;
}

// How leaves may reference triangles, from strictest to loosest.
enum class Refs {
    Once,          // each triangle in exactly one leaf
    Repeated,      // a triangle in one or more leaves (a refitted SBVH: its boxes are whole again)
    Partial,       // as Repeated, and a leaf box may be a clipped piece: inside its triangles' box,
                   // never empty (GridBvhSplit's partial triangles)
    SpatialSplit,  // as Partial, and an inner box need only contain its children's (SBVH)
};

struct TreeShape {
    int max_depth = 0;  // inner nodes on the longest root-to-leaf path
    size_t leaves = 0;
    size_t multi_prim_leaves = 0;
};

// Checks every invariant of a canonical BVH built over `triangles` with
// leaves of at most `max_leaf_size`; returns its shape. Guarded against
// malformed trees (bad links, indices, runaway depth), so a broken builder
// fails the test instead of crashing it.
inline TreeShape check_bvh(const Bvh& bvh, std::span<const Triangle> triangles, int max_leaf_size,
                           Refs refs = Refs::Once) {
    TreeShape shape;
    const bool once = refs == Refs::Once;
    const bool clipped_leaves = refs == Refs::Partial || refs == Refs::SpatialSplit;
    const bool exact_parents = refs != Refs::SpatialSplit;
    if (triangles.empty()) {
        EXPECT_TRUE(bvh.nodes.empty());
        EXPECT_TRUE(bvh.prim_indices.empty());
        return shape;
    }
    if (once) {
        EXPECT_EQ(bvh.prim_indices.size(), triangles.size());
    } else {
        EXPECT_GE(bvh.prim_indices.size(), triangles.size());
    }
    if (bvh.nodes.empty()) {
        ADD_FAILURE() << "no nodes for " << triangles.size() << " triangles";
        return shape;
    }
    std::vector<int> slot_seen(bvh.prim_indices.size(), 0);
    std::vector<int> prim_seen(triangles.size(), 0);
    // Walks the subtree of node `index` whose children pair (if any) must sit at
    // `base`; returns the first index after its descendants (depth-first layout).
    auto walk = [&](auto&& self, uint32_t index, uint32_t base, int depth) -> uint32_t {
        const BvhNode& node = bvh.nodes[index];
        if (node.is_leaf()) {
            shape.max_depth = std::max(shape.max_depth, depth);
            ++shape.leaves;
            shape.multi_prim_leaves += node.count > 1;
            EXPECT_LE(node.count, static_cast<uint32_t>(max_leaf_size));
            EXPECT_LE(size_t{node.first} + node.count, bvh.prim_indices.size());
            Box3f prims;
            for (uint32_t slot = node.first; slot < node.first + node.count && slot < slot_seen.size(); ++slot) {
                ++slot_seen[slot];
                const uint32_t prim = bvh.prim_indices[slot];
                if (prim >= triangles.size()) {
                    ADD_FAILURE() << "prim index out of range: " << prim;
                    continue;
                }
                ++prim_seen[prim];
                prims.extend(triangles[prim].bounds());
            }
            if (clipped_leaves) {
                EXPECT_TRUE(prims.contains(node.bounds)) << "leaf " << index << " box is outside its triangles' box";
                EXPECT_FALSE(node.bounds.is_empty()) << "leaf " << index;
            } else {
                EXPECT_TRUE(same_box(node.bounds, prims)) << "leaf " << index << " box is not its triangles' box";
            }
            return base;
        }
        EXPECT_EQ(node.first, base) << "children of node " << index << " are not in depth-first order";
        if (node.first != base || size_t{base} + 2 > bvh.nodes.size()) return base;
        const BvhNode& left = bvh.nodes[base];
        const BvhNode& right = bvh.nodes[base + 1];
        EXPECT_TRUE(node.bounds.contains(left.bounds)) << "node " << index;
        EXPECT_TRUE(node.bounds.contains(right.bounds)) << "node " << index;
        if (exact_parents) {
            EXPECT_TRUE(same_box(node.bounds, merge(left.bounds, right.bounds)))
                << "node " << index << " box is not its children's union";
        }
        if (depth > 10 * kBvhMaxDepth) {  // far past the limit: stop before the stack does
            ADD_FAILURE() << "runaway depth";
            return base;
        }
        const uint32_t after_left = self(self, base, base + 2, depth + 1);
        return self(self, base + 1, after_left, depth + 1);
    };
    const uint32_t end = walk(walk, 0, 1, 0);
    EXPECT_EQ(end, bvh.nodes.size()) << "unreachable nodes";
    EXPECT_TRUE(std::all_of(slot_seen.begin(), slot_seen.end(), [](int n) { return n == 1; }))
        << "a leaf slot is used twice or never";
    if (once) {
        EXPECT_TRUE(std::all_of(prim_seen.begin(), prim_seen.end(), [](int n) { return n == 1; }))
            << "a triangle is in no leaf or in two";
    } else {
        EXPECT_TRUE(std::all_of(prim_seen.begin(), prim_seen.end(), [](int n) { return n >= 1; }))
            << "a triangle is in no leaf";
    }
    EXPECT_LE(shape.max_depth, kBvhMaxDepth);
    EXPECT_EQ(shape.leaves, bvh.leaf_count());
    EXPECT_EQ(bvh.nodes.size(), 2 * shape.leaves - 1);
    return shape;
}

}  // namespace rf::test
