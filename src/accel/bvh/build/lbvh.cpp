// LBVH builder (Karras 2012, "Maximizing Parallelism in the Construction of
// BVHs, Octrees, and k-d Trees").
//
//  1. 30-bit (10 per axis) or 63-bit (21 per axis) Morton codes of the
//     triangles' box centres in the centroid bounds (morton_tree.cpp; each
//     triangle's box is computed once and reused for the leaves).
//  2. Parallel LSD radix sort of (code, triangle) pairs (morton_radix_sort.cpp;
//     30-bit codes packed with the triangle index into one 64-bit word).
//  3. Karras's inner-node construction: inner node i (of n - 1) finds the
//     direction and extent of its range and its split by binary searches on
//     the length of common code prefixes, all nodes independently. Equal
//     codes are told apart by their sorted positions (the prefix of
//     code ++ position), so duplicate codes still give a binary tree.
//  4. Bottom-up refit, children before parents: each inner node gets its box,
//     count, SAH cost, and whether <= max_leaf_size primitives are cheaper as
//     one leaf. Done as a post-order walk from the root (a node's range and
//     its split give its children's ranges), in parallel tasks over large
//     ranges, rather than by leaves climbing with atomic counters: the same
//     nodes, without the atomics and the parent arrays. Its depth is bounded
//     by the key length (prefixes grow strictly downwards).
//  5. The shared emitter (morton_tree.cpp) bounds the depth to kBvhMaxDepth
//     and writes the canonical depth-first layout; the leaves are the sorted
//     positions in order, so the sorted order becomes the primitive indices.
// Every step is independent of the thread count, so the tree is too.
#include "accel/bvh/build/lbvh.h"

#include <algorithm>
#include <bit>
#include <memory>
#include <string>

#include "accel/bvh/build/morton_tree.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using morton::kLeafRef;

constexpr uint32_t kGrain = 8 * 1024;
constexpr uint32_t kParallelRefit = 8 * 1024;  // primitives per subtree to refit as its own task

template <class Key>
class KarrasBuilder {
public:
    KarrasBuilder(const Key* keys, uint32_t n, morton::RawTree& tree) : keys_(keys), n_(n), tree_(tree) {}

    // Builds the inner nodes 0 .. n-2 (root 0) and refits them; n >= 2.
    void build() {
        budgeted_resize(tree_.nodes, n_ - 1, "LBVH: inner nodes");
        morton::RawNode* nodes = tree_.nodes.data();
        parallel::for_range(0u, n_ - 1, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) build_inner(keys_, n_, nodes, i);
        });
        refit(0, 0, n_ - 1);
    }

private:
    // Length of the common prefix of (code, position) at sorted positions i
    // and j; -1 outside the array.
    [[gnu::always_inline]] static int delta(const Key* keys, uint32_t n, int64_t i, int64_t j) {
        if (static_cast<uint64_t>(j) >= n) return -1;
        const Key a = keys[i], b = keys[j];
        const uint32_t positions = static_cast<uint32_t>(i ^ j);
        if constexpr (sizeof(Key) == 4) {
            // Codes above positions: the prefix of the 64-bit word is the
            // code prefix where the codes differ, else 32 + the position prefix.
            return std::countl_zero((static_cast<uint64_t>(a ^ b) << 32) | positions);
        } else {
            if (a != b) return std::countl_zero(static_cast<uint64_t>(a ^ b));
            return 64 + std::countl_zero(positions);
        }
    }

    static void build_inner(const Key* keys, uint32_t n, morton::RawNode* nodes, uint32_t index) {
        auto delta = [keys, n](int64_t i, int64_t j) { return KarrasBuilder::delta(keys, n, i, j); };
        const int64_t i = index;
        // Direction of the range: towards the neighbour sharing the longer prefix.
        const int next = delta(i, i + 1), previous = delta(i, i - 1);
        const int d = next - previous > 0 ? 1 : -1;
        const int delta_min = d > 0 ? previous : next;  // delta(i, i - d)
        // Upper bound on the range length, then its exact other end j.
        int64_t max_length = 2;
        while (delta(i, i + max_length * d) > delta_min) max_length *= 2;
        int64_t length = 0;
        for (int64_t step = max_length / 2; step >= 1; step /= 2) {
            if (delta(i, i + (length + step) * d) > delta_min) length += step;
        }
        const int64_t j = i + length * d;
        // Split: the last position sharing more than the node's prefix with i.
        const int delta_node = delta(i, j);
        int64_t split = 0;
        int64_t step = length;
        do {
            step = (step + 1) / 2;
            if (delta(i, i + (split + step) * d) > delta_node) split += step;
        } while (step > 1);
        const int64_t gamma = i + split * d + std::min(d, 0);

        const uint32_t g = static_cast<uint32_t>(gamma);
        const bool left_is_leaf = std::min(i, j) == gamma;
        const bool right_is_leaf = std::max(i, j) == gamma + 1;
        morton::RawNode& node = nodes[index];
        node.child[0] = left_is_leaf ? (kLeafRef | g) : g;
        node.child[1] = right_is_leaf ? (kLeafRef | (g + 1)) : g + 1;
    }

    // Finalizes the subtree at inner node `index` over sorted positions
    // [first, last], children before parents. Its left child (inner node or
    // leaf) is numbered by the split position gamma, so the children's ranges
    // are [first, gamma] and [gamma + 1, last]; large ranges are split into
    // parallel tasks. Depth is at most the key length in bits (prefixes grow
    // strictly downwards), so recursion is safe.
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
    void refit_serial(uint32_t index) {
        const morton::RawNode& node = tree_.nodes[index];
        const uint32_t left = node.child[0], right = node.child[1];
        if (!morton::is_leaf_ref(left)) refit_serial(left);
        if (!morton::is_leaf_ref(right)) refit_serial(right);
        tree_.finalize_unit_leaves(index, left, right);
    }

    const Key* keys_;
    uint32_t n_;
    morton::RawTree& tree_;
};

template <class Key>
Bvh build_with_keys(std::span<const Triangle> triangles, const BuildOptions& options) {
    morton::RawTree tree(triangles, options);
    morton::Buffer<Key> keys;
    tree.sort_by_morton_codes(keys);
    const uint32_t n = tree.size();
    if (n == 0) return {};
    if (n == 1) return tree.emit_in_order(kLeafRef | 0u);
    KarrasBuilder<Key>(keys.data(), n, tree).build();
    keys.clear();
    return tree.emit_in_order(0);
}

}  // namespace

Bvh build_lbvh(std::span<const Triangle> triangles, const BuildOptions& options, int morton_bits) {
    if (morton_bits != 30 && morton_bits != 63) {
        throw Error("LBVH: Morton code bits must be 30 or 63, got " + std::to_string(morton_bits));
    }
    return parallel::with_threads(options.threads, [&] {
        return morton_bits == 30 ? build_with_keys<uint32_t>(triangles, options)
                                 : build_with_keys<uint64_t>(triangles, options);
    });
}

}  // namespace rf
