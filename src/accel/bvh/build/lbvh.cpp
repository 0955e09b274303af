// LBVH builder (Karras 2012, "Maximizing Parallelism in the Construction of
// BVHs, Octrees, and k-d Trees").
//
//  1. 30-bit (10 per axis) or 63-bit (21 per axis) Morton codes of the
//     triangles' box centres in the centroid bounds (morton_tree.cpp).
//  2. Parallel LSD radix sort of (code, triangle) pairs (morton_radix_sort.cpp).
//  3. Karras's inner-node construction: inner node i (of n - 1) finds the
//     direction and extent of its range and its split by binary searches on
//     the length of common code prefixes, all nodes independently. Equal
//     codes are told apart by their sorted positions (the prefix of
//     code ++ position), so duplicate codes still give a binary tree.
//  4. Bottom-up refit: every leaf walks towards the root; at each inner node
//     an atomic counter lets the second arriving child finish the node (box,
//     count, SAH cost, and whether <= max_leaf_size primitives are cheaper as
//     one leaf), the first one stops.
//  5. The shared emitter (morton_tree.cpp) bounds the depth to kBvhMaxDepth
//     and writes the canonical depth-first layout.
// Every step is independent of the thread count, so the tree is too.
#include "accel/bvh/build/lbvh.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <memory>
#include <string>

#include "accel/bvh/build/morton_radix_sort.h"
#include "accel/bvh/build/morton_tree.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using morton::kLeafRef;

constexpr uint32_t kGrain = 8 * 1024;

template <class Key>
class KarrasBuilder {
public:
    KarrasBuilder(std::span<const Key> keys, morton::RawTree& tree) : keys_(keys), tree_(tree) {}

    // Builds the inner nodes 0 .. n-2 (root 0) and refits them; n >= 2.
    void build() {
        const uint32_t n = static_cast<uint32_t>(keys_.size());
        budgeted_resize(tree_.nodes, n - 1, "LBVH: inner nodes");
        budgeted_resize(inner_parent_, n - 1, "LBVH: inner parents");
        budgeted_resize(leaf_parent_, n, "LBVH: leaf parents");
        parallel::for_range(0u, n - 1, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) build_inner(i);
        });
        refit();
    }

private:
    // Length of the common prefix of (code, position) at sorted positions i
    // and j; -1 outside the array.
    int delta(int64_t i, int64_t j) const {
        if (j < 0 || j >= static_cast<int64_t>(keys_.size())) return -1;
        const Key a = keys_[static_cast<size_t>(i)], b = keys_[static_cast<size_t>(j)];
        if (a != b) return std::countl_zero(static_cast<Key>(a ^ b));
        return static_cast<int>(8 * sizeof(Key)) + std::countl_zero(static_cast<uint32_t>(i ^ j));
    }

    void build_inner(uint32_t index) {
        const int64_t i = index;
        // Direction of the range: towards the neighbour sharing the longer prefix.
        const int d = delta(i, i + 1) - delta(i, i - 1) > 0 ? 1 : -1;
        const int delta_min = delta(i, i - d);
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
        morton::RawNode& node = tree_.nodes[index];
        node.child[0] = left_is_leaf ? (kLeafRef | g) : g;
        node.child[1] = right_is_leaf ? (kLeafRef | (g + 1)) : g + 1;
        if (left_is_leaf) leaf_parent_[g] = index; else inner_parent_[g] = index;
        if (right_is_leaf) leaf_parent_[g + 1] = index; else inner_parent_[g + 1] = index;
    }

    void refit() {
        const uint32_t n = static_cast<uint32_t>(keys_.size());
        checked_array_bytes("LBVH: refit flags", n - 1, sizeof(std::atomic<uint32_t>));
        std::unique_ptr<std::atomic<uint32_t>[]> arrivals(new std::atomic<uint32_t>[n - 1]);
        parallel::for_range(0u, n - 1, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) arrivals[i].store(0, std::memory_order_relaxed);
        });
        parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t leaf = lo; leaf != hi; ++leaf) {
                uint32_t node = leaf_parent_[leaf];
                // acq_rel: the second arrival sees everything the first wrote below.
                while (arrivals[node].fetch_add(1, std::memory_order_acq_rel) == 1) {
                    tree_.finalize(node);
                    if (node == 0) break;
                    node = inner_parent_[node];
                }
            }
        });
    }

    std::span<const Key> keys_;
    morton::RawTree& tree_;
    std::vector<uint32_t> inner_parent_;
    std::vector<uint32_t> leaf_parent_;
};

template <class Key>
Bvh build_with_keys(std::span<const Triangle> triangles, const BuildOptions& options, int bits) {
    morton::RawTree tree(triangles, options);
    std::vector<Key> keys;
    std::vector<uint32_t> order;
    morton::compute_morton_codes(triangles, keys, order);
    if (keys.empty()) return {};
    radix_sort_pairs(keys, order, bits);
    tree.set_order(std::move(order));
    if (keys.size() == 1) return tree.emit(kLeafRef | 0u);
    KarrasBuilder<Key>(keys, tree).build();
    return tree.emit(0);
}

}  // namespace

Bvh build_lbvh(std::span<const Triangle> triangles, const BuildOptions& options, int morton_bits) {
    if (morton_bits != 30 && morton_bits != 63) {
        throw Error("LBVH: Morton code bits must be 30 or 63, got " + std::to_string(morton_bits));
    }
    return parallel::with_threads(options.threads, [&] {
        return morton_bits == 30 ? build_with_keys<uint32_t>(triangles, options, 30)
                                 : build_with_keys<uint64_t>(triangles, options, 63);
    });
}

}  // namespace rf
