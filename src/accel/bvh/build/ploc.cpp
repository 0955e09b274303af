// PLOC builder (Meister and Bittner 2018, "Parallel Locally-Ordered
// Clustering for Bounding Volume Hierarchy Construction").
//
//  1. 63-bit Morton codes of the triangles' box centres, radix-sorted: the
//     initial clusters are the triangles along the Morton curve.
//  2. Iterate until one cluster is left:
//     a. nearest neighbour: every cluster i looks at the clusters within
//        +-options.ploc_radius positions and picks the one whose merged box
//        has the smallest surface area (ties broken by a total order on
//        pairs, so the globally closest pair is always mutual and every
//        iteration merges at least once);
//     b. merge: mutual nearest neighbours i < j become one inner node, which
//        takes position i; j is dropped;
//     c. compaction by prefix sums over fixed blocks (survivors and new
//        nodes), so node numbering depends on the input only.
//  3. Leaves: the raw tree has one triangle per leaf; the shared emitter
//     (morton_tree.cpp) collapses subtrees of <= max_leaf_size triangles where
//     the SAH prefers one leaf, bounds the depth to kBvhMaxDepth and writes
//     the canonical depth-first layout.
#include "accel/bvh/build/ploc.h"

#include <algorithm>
#include <cfloat>

#include "accel/bvh/build/morton_radix_sort.h"
#include "accel/bvh/build/morton_tree.h"
#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using morton::kLeafRef;

constexpr uint32_t kBlock = 4096;  // clusters per compaction block
constexpr uint32_t kSearchGrain = 1024;

class PlocBuilder {
public:
    PlocBuilder(std::span<const Triangle> triangles, const BuildOptions& options)
        : tree_(triangles, options), radius_(static_cast<uint32_t>(std::clamp(options.ploc_radius, 1, 1 << 16))) {}

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
    // Tie-break between equal areas, the same from both ends of a pair so
    // that the order on pairs is total (the globally closest pair is then
    // always mutual): nearer positions first, then pairs starting at an even
    // position, then the lower start. Among identical boxes (duplicate
    // triangles) this pairs (0,1), (2,3), ..., halving them every iteration;
    // "lowest position first" would merge one pair per iteration.
    static bool closer_pair(uint32_t i, uint32_t j, uint32_t k) {
        const uint32_t dj = j > i ? j - i : i - j, dk = k > i ? k - i : i - k;
        if (dj != dk) return dj < dk;
        const uint32_t sj = std::min(i, j), sk = std::min(i, k);
        if ((sj & 1u) != (sk & 1u)) return (sj & 1u) == 0;
        return sj < sk;
    }

    void find_neighbours(uint32_t count) {
        parallel::for_range(0u, count, kSearchGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) {
                const Box3f box = boxes_[i];
                const uint32_t begin = i > radius_ ? i - radius_ : 0;
                const uint32_t end = std::min(count, i + radius_ + 1);
                float best = FLT_MAX;
                uint32_t best_j = i;
                for (uint32_t j = begin; j != end; ++j) {
                    if (j == i) continue;
                    const float area = morton::half_area(morton::box_union(box, boxes_[j]));
                    if (best_j == i || area < best || (area == best && closer_pair(i, j, best_j))) {
                        best = area;
                        best_j = j;
                    }
                }
                neighbour_[i] = best_j;
            }
        });
    }

    // Merges mutual nearest neighbours into new nodes numbered from
    // `next_node` and compacts the clusters into next_refs_/next_boxes_;
    // returns the number of merges.
    uint32_t merge_and_compact(uint32_t count, uint32_t next_node) {
        const uint32_t blocks = (count + kBlock - 1) / kBlock;
        block_survivors_.assign(blocks + 1, 0);
        block_merges_.assign(blocks + 1, 0);
        auto mutual = [&](uint32_t i) { return neighbour_[neighbour_[i]] == i; };
        parallel::for_range(0u, blocks, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t b = lo; b != hi; ++b) {
                uint32_t survivors = 0, merges = 0;
                for (uint32_t i = b * kBlock, end = std::min(count, i + kBlock); i != end; ++i) {
                    const bool m = mutual(i);
                    survivors += !m || i < neighbour_[i];
                    merges += m && i < neighbour_[i];
                }
                block_survivors_[b + 1] = survivors;
                block_merges_[b + 1] = merges;
            }
        });
        for (uint32_t b = 0; b < blocks; ++b) {
            block_survivors_[b + 1] += block_survivors_[b];
            block_merges_[b + 1] += block_merges_[b];
        }
        parallel::for_range(0u, blocks, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t b = lo; b != hi; ++b) {
                uint32_t at = block_survivors_[b], node = next_node + block_merges_[b];
                for (uint32_t i = b * kBlock, end = std::min(count, i + kBlock); i != end; ++i) {
                    const uint32_t j = neighbour_[i];
                    if (neighbour_[j] != i) {
                        next_refs_[at] = refs_[i];
                        next_boxes_[at] = boxes_[i];
                        ++at;
                    } else if (i < j) {
                        tree_.finalize(node, refs_[i], refs_[j]);
                        next_refs_[at] = node;
                        next_boxes_[at] = tree_.nodes[node].box;
                        ++at;
                        ++node;
                    }
                }
            }
        });
        return block_merges_[blocks];
    }

    morton::RawTree tree_;
    uint32_t radius_;
    std::vector<uint32_t> refs_, next_refs_;
    std::vector<Box3f> boxes_, next_boxes_;
    std::vector<uint32_t> neighbour_;
    std::vector<uint32_t> block_survivors_, block_merges_;
};

}  // namespace

Bvh build_ploc(std::span<const Triangle> triangles, const BuildOptions& options) {
    PlocBuilder builder(triangles, options);
    return parallel::with_threads(options.threads, [&] { return builder.build(); });
}

}  // namespace rf
