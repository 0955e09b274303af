// LBVH builder (Karras 2012, "Maximizing Parallelism in the Construction of
// BVHs, Octrees, and k-d Trees").
//
//  1. 30-bit (10 per axis) or 63-bit (21 per axis) Morton codes of the
//     triangles' box centres in the centroid bounds (morton_tree.cpp; each
//     triangle's box is computed once and reused for the leaves).
//  2. Parallel LSD radix sort of (code, triangle) pairs (morton_radix_sort.cpp;
//     30-bit codes packed with the triangle index into one 64-bit word).
//  3. Karras's inner-node construction (karras_tree_steps.h, shared with the CUDA
//     builder): inner node i (of n - 1) finds the direction and extent of its
//     range and its split by binary searches on the length of common code
//     prefixes, all nodes independently. Equal codes are told apart by their
//     sorted positions (the prefix of code ++ position), so duplicate codes
//     still give a binary tree.
//  4. Bottom-up refit, children before parents: each inner node gets its box,
//     count, SAH cost, and whether <= max_leaf_size primitives are cheaper as
//     one leaf. Done as a post-order walk from the root (a node's range and
//     its split give its children's ranges), in parallel tasks over large
//     ranges, rather than by leaves climbing with atomic counters: the same
//     nodes, without the atomics and the parent arrays. Its depth is bounded
//     by the key length (prefixes grow strictly downwards). The CUDA builder
//     (backend/cuda/lbvh_build.cu) climbs with the counters for the boxes
//     and then hands its tree to the same refit (emit_karras_tree).
//  5. The shared emitter (morton_tree.cpp) bounds the depth to kBvhMaxDepth
//     and writes the canonical depth-first layout; the leaves are the sorted
//     positions in order, so the sorted order becomes the primitive indices.
// Every step is independent of the thread count, so the tree is too.
#include "accel/bvh/builders/lbvh.h"

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/lbvh_emit.h"
#include "accel/bvh/builders/morton_tree.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using morton::kLeafRef;
static_assert(karras::kLeafRef == morton::kLeafRef, "Karras trees are raw trees as they are");

constexpr uint32_t kGrain = 8 * 1024;
constexpr uint32_t kParallelRefit = 8 * 1024;  // primitives per subtree to refit as its own task

// Finalizes the inner nodes of a Karras radix tree whose child references
// are set, children before parents, with box, count, SAH cost and collapse
// decision (morton::RawTree::finalize_unit_leaves).
class KarrasRefit {
public:
    explicit KarrasRefit(morton::RawTree& tree) : tree_(tree) {}

    // Finalizes the subtree at inner node `index` over sorted positions
    // [first, last]. Its left child (inner node or leaf) is numbered by the
    // split position gamma, so the children's ranges are [first, gamma] and
    // [gamma + 1, last]; large ranges are split into parallel tasks. Depth is
    // at most the key length in bits (prefixes grow strictly downwards), so
    // recursion is safe.
    void refit(uint32_t index, uint32_t first, uint32_t last) {
        if (last - first <= kParallelRefit) return refit_serial(index);
        const morton::RawNode& node = tree_.nodes[index];
        const uint32_t left = node.child[0], right = node.child[1];
        const uint32_t gamma = left & ~kLeafRef;
        if (morton::is_leaf_ref(left)) {
            refit(right, gamma + 1, last);
        } else if (morton::is_leaf_ref(right)) {
            refit(left, first, gamma);
        } else {
            parallel::invoke([&] { refit(left, first, gamma); }, [&] { refit(right, gamma + 1, last); });
        }
        tree_.finalize_unit_leaves(index, left, right);
    }

private:
    void refit_serial(uint32_t index) {
        const morton::RawNode& node = tree_.nodes[index];
        const uint32_t left = node.child[0], right = node.child[1];
        if (!morton::is_leaf_ref(left)) refit_serial(left);
        if (!morton::is_leaf_ref(right)) refit_serial(right);
        tree_.finalize_unit_leaves(index, left, right);
    }

    morton::RawTree& tree_;
};

// Builds the inner nodes 0 .. n-2 (root 0) of n >= 2 sorted keys with
// karras::build_inner (no parent links: the refit walks down from the root)
// and refits them.
template <class Key>
void build_karras_tree(const Key* keys, uint32_t n, morton::RawTree& tree) {
    budgeted_resize(tree.nodes, n - 1, "LBVH: inner nodes");
    morton::RawNode* nodes = tree.nodes.data();
    parallel::for_range(0u, n - 1, kGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) karras::build_inner(keys, n, i, nodes[i].child, nullptr, nullptr);
    });
    KarrasRefit(tree).refit(0, 0, n - 1);
}

template <class Key>
Bvh build_with_keys(std::span<const Triangle> triangles, const BvhBuildConfig& config) {
    morton::RawTree tree(triangles, config);
    morton::Buffer<Key> keys;
    tree.sort_by_morton_codes(keys);
    const uint32_t n = tree.size();
    if (n == 0) return {};
    if (n == 1) return tree.emit_in_order(kLeafRef | 0u);
    build_karras_tree(keys.data(), n, tree);
    keys.clear();
    return tree.emit_in_order(0);
}

}  // namespace

Bvh emit_karras_tree(std::span<const Triangle> triangles, const BvhBuildConfig& config, std::vector<uint32_t>&& order,
                     std::span<const uint32_t> children) {
    if (order.size() != triangles.size()) throw Error("LBVH emission: order and triangles differ in size");
    const uint32_t n = static_cast<uint32_t>(order.size());
    if (n == 0) return {};
    if (children.size() != 2 * (size_t{n} - 1)) throw Error("LBVH emission: expected 2 (n - 1) child references");
    morton::RawTree tree(triangles, config);
    tree.set_order(std::move(order));
    if (n == 1) return tree.emit_in_order(kLeafRef | 0u);
    budgeted_resize(tree.nodes, n - 1, "LBVH: inner nodes");
    morton::RawNode* nodes = tree.nodes.data();
    parallel::for_range(0u, n - 1, kGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) {
            nodes[i].child[0] = children[2 * size_t{i}];
            nodes[i].child[1] = children[2 * size_t{i} + 1];
        }
    });
    KarrasRefit(tree).refit(0, 0, n - 1);
    return tree.emit_in_order(0);
}

Bvh build_lbvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, int morton_bits) {
    if (morton_bits != 30 && morton_bits != 63) {
        throw Error("LBVH: Morton code bits must be 30 or 63, got " + std::to_string(morton_bits));
    }
    return morton_bits == 30 ? build_with_keys<uint32_t>(triangles, config)
                             : build_with_keys<uint64_t>(triangles, config);
}

}  // namespace rf
