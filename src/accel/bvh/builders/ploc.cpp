// PLOC builder (Meister and Bittner 2018, "Parallel Locally-Ordered
// Clustering for Bounding Volume Hierarchy Construction").
//
//  1. 63-bit Morton codes of the triangles' box centres, radix-sorted: the
//     initial clusters are the triangles along the Morton curve.
//  2. Iterate until one cluster is left (the per-cluster steps are
//     ploc_steps.h's, shared with the CUDA builder, backend/cuda/ploc_build.cu):
//     a. nearest neighbour: every cluster i looks at the clusters within
//        +-PlocOptions::radius positions and picks the one whose merged box
//        has the smallest surface area (ties broken by a total order on
//        pairs, so the globally closest pair is always mutual and every
//        iteration merges at least once);
//     b. merge: mutual nearest neighbours i < j become one inner node, which
//        takes position i; j is dropped;
//     c. compaction by an exclusive prefix sum of (survivors, merges) over
//        the clusters, computed here over fixed blocks: new positions and
//        node numbers follow the cluster order, so they depend on the input
//        only (and equal the device's global scan).
//  3. Leaves: the raw tree has one triangle per leaf; the shared emitter
//     (morton_tree.cpp) collapses subtrees of <= max_leaf_size triangles where
//     the SAH prefers one leaf, bounds the depth to kBvhMaxDepth and writes
//     the canonical depth-first layout. emit_ploc_tree (ploc_emit.h) does the
//     same for a clustering done on the device.
#include "accel/bvh/builders/ploc.h"

#include <algorithm>
#include <string>
#include <utility>

#include "accel/bvh/builders/morton_radix_sort.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel/bvh/builders/ploc_emit.h"
#include "accel/bvh/builders/ploc_steps.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using morton::kLeafRef;
static_assert(ploc::kLeafRef == morton::kLeafRef, "PLOC clusters are raw-tree references");

constexpr uint32_t kBlock = 4096;  // clusters per compaction block
constexpr uint32_t kSearchGrain = 1024;
constexpr uint32_t kFinalizeGrain = 4096;

class PlocBuilder {
public:
    PlocBuilder(std::span<const Triangle> triangles, const BvhBuildConfig& config, const PlocOptions& ploc_options)
        : tree_(triangles, config), radius_(ploc::clamp_radius(ploc_options.radius)) {}

    Bvh build() {
        std::vector<uint64_t> keys;
        std::vector<uint32_t> order;
        morton::compute_morton_codes(tree_.triangles, keys, order);
        const uint32_t n = static_cast<uint32_t>(keys.size());
        if (n == 0) return {};
        radix_sort_pairs(keys, order, 63);
        keys = {};
        tree_.set_order(std::move(order));
        if (n == 1) return tree_.emit(kLeafRef | 0u);

        budgeted_resize(tree_.nodes, n - 1, "PLOC: nodes");
        budgeted_resize(refs_, n, "PLOC: clusters");
        budgeted_resize(boxes_, n, "PLOC: cluster boxes");
        budgeted_resize(next_refs_, n, "PLOC: clusters");
        budgeted_resize(next_boxes_, n, "PLOC: cluster boxes");
        budgeted_resize(neighbour_, n, "PLOC: neighbours");
        parallel::for_range(0u, n, 16 * 1024u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) {
                refs_[i] = kLeafRef | i;
                boxes_[i] = tree_.boxes[i];
            }
        });
        uint32_t count = n, next_node = 0;
        while (count > 1) {
            find_neighbours(count);
            const uint32_t merged = merge_and_compact(count, next_node);
            next_node += merged;
            count -= merged;
            refs_.swap(next_refs_);
            boxes_.swap(next_boxes_);
        }
        return tree_.emit(refs_[0]);
    }

private:
    void find_neighbours(uint32_t count) {
        parallel::for_range(0u, count, kSearchGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) neighbour_[i] = ploc::nearest_neighbour(boxes_.data(), count, radius_, i);
        });
    }

    // Merges mutual nearest neighbours into new nodes numbered from
    // `next_node` and compacts the clusters into next_refs_/next_boxes_;
    // returns the number of merges.
    uint32_t merge_and_compact(uint32_t count, uint32_t next_node) {
        const uint32_t blocks = (count + kBlock - 1) / kBlock;
        const uint32_t* neighbour = neighbour_.data();
        block_prefix_.assign(blocks + 1, 0);
        parallel::for_range(0u, blocks, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t b = lo; b != hi; ++b) {
                uint64_t sum = 0;
                for (uint32_t i = b * kBlock, end = std::min(count, i + kBlock); i != end; ++i) {
                    sum += ploc::compaction_flags(neighbour, i);
                }
                block_prefix_[b + 1] = sum;
            }
        });
        for (uint32_t b = 0; b < blocks; ++b) block_prefix_[b + 1] += block_prefix_[b];
        parallel::for_range(0u, blocks, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t b = lo; b != hi; ++b) {
                uint64_t prefix = block_prefix_[b];
                for (uint32_t i = b * kBlock, end = std::min(count, i + kBlock); i != end; ++i) {
                    const ploc::Placement p = ploc::place_cluster(neighbour, i, prefix, next_node);
                    prefix += (uint64_t{p.survives} << 32) | uint64_t{p.merges};
                    if (p.merges) {
                        tree_.finalize(p.node, refs_[i], refs_[p.partner]);
                        next_refs_[p.position] = p.node;
                        next_boxes_[p.position] = tree_.nodes[p.node].box;
                    } else if (p.survives) {
                        next_refs_[p.position] = refs_[i];
                        next_boxes_[p.position] = boxes_[i];
                    }
                }
            }
        });
        return static_cast<uint32_t>(block_prefix_[blocks] & 0xffffffffu);
    }

    morton::RawTree tree_;
    uint32_t radius_;
    std::vector<uint32_t> refs_, next_refs_;
    std::vector<Box3f> boxes_, next_boxes_;
    std::vector<uint32_t> neighbour_;
    std::vector<uint64_t> block_prefix_;  // (survivors << 32 | merges) before each block
};

// Every leaf and every node but the root referenced exactly once, each node
// only by a node of a later iteration.
void check_ploc_tree(uint32_t n, std::span<const uint32_t> children, std::span<const uint32_t> iteration_nodes) {
    if (children.size() != 2 * (size_t{n} - 1)) throw Error("PLOC emission: expected 2 (n - 1) child references");
    uint64_t total = 0;
    for (uint32_t nodes : iteration_nodes) total += nodes;
    if (total != n - 1) throw Error("PLOC emission: the iterations created " + std::to_string(total) +
                                    " nodes, expected " + std::to_string(n - 1));
    std::vector<uint8_t> used(2 * size_t{n} - 1, 0);  // leaves, then nodes
    uint32_t begin = 0;
    for (uint32_t nodes : iteration_nodes) {
        for (uint32_t node = begin; node != begin + nodes; ++node) {
            for (int c = 0; c < 2; ++c) {
                const uint32_t ref = children[2 * size_t{node} + c];
                const uint32_t index = ref & ~kLeafRef;
                const bool leaf = morton::is_leaf_ref(ref);
                if (leaf ? index >= n : index >= begin) {
                    throw Error("PLOC emission: node " + std::to_string(node) + " has an invalid child " +
                                std::to_string(ref));
                }
                if (used[leaf ? index : n + index]++ != 0) {
                    throw Error("PLOC emission: child " + std::to_string(ref) + " referenced twice");
                }
            }
        }
        begin += nodes;
    }
}

}  // namespace

Bvh build_ploc(std::span<const Triangle> triangles, const BvhBuildConfig& config, const PlocOptions& ploc_options) {
    PlocBuilder builder(triangles, config, ploc_options);
    return builder.build();
}

Bvh emit_ploc_tree(std::span<const Triangle> triangles, const BvhBuildConfig& config, std::vector<uint32_t>&& order,
                   std::span<const uint32_t> children, std::span<const uint32_t> iteration_nodes) {
    if (order.size() != triangles.size()) throw Error("PLOC emission: order and triangles differ in size");
    const uint32_t n = static_cast<uint32_t>(order.size());
    if (n == 0) return {};
    check_ploc_tree(n, children, iteration_nodes);
    morton::RawTree tree(triangles, config);
    tree.set_order(std::move(order));
    if (n == 1) return tree.emit(kLeafRef | 0u);
    budgeted_resize(tree.nodes, n - 1, "PLOC: nodes");
    // Children before parents: iteration by iteration, each in parallel.
    uint32_t begin = 0;
    for (uint32_t nodes : iteration_nodes) {
        parallel::for_range(begin, begin + nodes, kFinalizeGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) tree.finalize(i, children[2 * size_t{i}], children[2 * size_t{i} + 1]);
        });
        begin += nodes;
    }
    return tree.emit(n - 2);  // the last node created
}

}  // namespace rf
