// Helpers shared by the full-sweep SAH builder, the SBVH builder and the
// reinsertion optimizer: fast box growth, sortable float keys, a parallel
// merge sort, the depth-limit rule and the depth-first re-emission of a tree
// whose nodes were allocated in arbitrary (task) order.
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "backend/cpu/parallel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/memory_budget.h"

namespace rf::sweep {

// std::min/max compile to single instructions (the NaN-aware fminf/fmaxf
// behind Box3f::extend are library calls); builder inputs are finite.
inline Vec3f vmin(const Vec3f& a, const Vec3f& b) {
    return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3f vmax(const Vec3f& a, const Vec3f& b) {
    return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
inline void grow(Box3f& box, const Vec3f& lo, const Vec3f& hi) {
    box.lo = vmin(box.lo, lo);
    box.hi = vmax(box.hi, hi);
}
inline void grow(Box3f& box, const Box3f& b) { grow(box, b.lo, b.hi); }

// Maps a float to an unsigned integer with the same order (-0 just below +0),
// so that sorting (key << 32 | index) sorts by value with a total tie-break.
inline uint32_t sortable_key(float f) {
    const uint32_t bits = std::bit_cast<uint32_t>(f);
    return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}
inline uint64_t sort_key(float value, uint32_t index) {
    return (uint64_t{sortable_key(value)} << 32) | index;
}

// Levels of halving needed until `count` references fit in leaves of `leaf_size`.
inline int median_levels(uint64_t count, uint32_t leaf_size) {
    const uint64_t leaves = (count + leaf_size - 1) / leaf_size;
    return leaves <= 1 ? 0 : static_cast<int>(std::bit_width(leaves - 1));
}

// Merge sort of data[0, n) on TBB tasks (via backend/cpu/parallel.h); tmp has room
// for n values. Small ranges fall back to std::sort.
inline void parallel_sort(uint64_t* data, uint64_t* tmp, size_t n) {
    constexpr size_t kSerialSize = 32 * 1024;
    if (n <= kSerialSize) {
        std::sort(data, data + n);
        return;
    }
    const size_t half = n / 2;
    parallel::invoke([&] { parallel_sort(data, tmp, half); },
                     [&] { parallel_sort(data + half, tmp + half, n - half); });
    std::merge(data, data + half, data + half, data + n, tmp);
    std::copy(tmp, tmp + n, data);
}

// A node of a tree under construction: inner nodes name their two children
// (anywhere in the node array), leaves a range of a primitive slot array.
struct ScratchNode {
    Box3f bounds;
    uint32_t a = 0;      // inner: left child; leaf: first slot
    uint32_t b = 0;      // inner: right child; leaf: slot count
    bool leaf = false;
};

// Copies the tree under scratch[root] into the canonical layout: nodes in
// depth-first order with each children pair adjacent (a node's pair, then the
// left subtree's descendants, then the right's), and leaf slots renumbered in
// the order the leaves are laid out.
inline Bvh emit_depth_first(std::span<const ScratchNode> scratch, uint32_t root, uint32_t node_count,
                            std::span<const uint32_t> slots, size_t slot_count) {
    Bvh bvh;
    budgeted_resize(bvh.nodes, node_count, "BVH nodes");
    budgeted_resize(bvh.prim_indices, slot_count, "BVH primitive indices");
    std::vector<std::pair<uint32_t, uint32_t>> stack;  // (scratch node, output index)
    stack.reserve(2 * kBvhMaxDepth + 4);
    stack.emplace_back(root, 0u);
    uint32_t next_node = 1, next_slot = 0;
    while (!stack.empty()) {
        const auto [from, at] = stack.back();
        stack.pop_back();
        const ScratchNode& node = scratch[from];
        BvhNode& out = bvh.nodes[at];
        out.bounds = node.bounds;
        if (node.leaf) {
            out.first = next_slot;
            out.count = node.b;
            for (uint32_t i = 0; i < node.b; ++i) bvh.prim_indices[next_slot++] = slots[node.a + i];
            continue;
        }
        out.first = next_node;
        out.count = 0;
        next_node += 2;
        stack.emplace_back(node.b, out.first + 1);  // popped after the left subtree is done
        stack.emplace_back(node.a, out.first);
    }
    return bvh;
}

}  // namespace rf::sweep
