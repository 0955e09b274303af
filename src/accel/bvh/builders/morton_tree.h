// Shared machinery of the Morton-ordered builders (LBVH, Karras 2012; HLBVH2,
// Garanzha 2014 ch. 5; PLOC, Meister and Bittner 2018): Morton codes of the
// triangles' box centres, and an intermediate binary tree ("raw tree") whose
// leaves are runs of Morton-sorted primitives. The raw tree is turned into
// the canonical rf::Bvh by one emitter:
//   - bottom-up, while a builder creates inner nodes, finalize() computes
//     each node's box, primitive count, SAH cost, and whether the subtree is
//     cheaper as one leaf (only possible for <= max_leaf_size primitives);
//   - emit() then rebuilds subtrees that would end deeper than kBvhMaxDepth
//     (Morton trees can: exponentially spaced input, long runs of equal
//     codes) as balanced halvings of their primitives, and writes the nodes
//     in depth-first order with siblings adjacent, in parallel.
#pragma once

#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/morton_buffer.h"
#include "accel/bvh/builders/raw_tree_emit_steps.h"
#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::morton {

// Child references: inner node index, or kLeafRef | sorted position of the
// first primitive of a leaf run.
inline constexpr uint32_t kLeafRef = 0x80000000u;
inline bool is_leaf_ref(uint32_t ref) { return (ref & kLeafRef) != 0; }

// Box growth with std::min/max semantics (single instructions; inputs are
// finite): the one the device builders use too.
using karras::box_union;

// A triangle's box as the Morton builders compute it (this min/max order;
// the device's morton_sort.cu mirrors it, so signed zeros agree).
inline Box3f triangle_box(const Triangle& t) {
    Box3f b;
    b.lo = Vec3f(std::min(t.v0.x, std::min(t.v1.x, t.v2.x)), std::min(t.v0.y, std::min(t.v1.y, t.v2.y)),
                 std::min(t.v0.z, std::min(t.v1.z, t.v2.z)));
    b.hi = Vec3f(std::max(t.v0.x, std::max(t.v1.x, t.v2.x)), std::max(t.v0.y, std::max(t.v1.y, t.v2.y)),
                 std::max(t.v0.z, std::max(t.v1.z, t.v2.z)));
    return b;
}

struct RawNode {
    // Left uninitialised when a node array is sized (finalize() sets every
    // field the emitter reads); the union keeps Box3f's constructor out.
    RawNode() {}
    union {
        Box3f box;
    };
    uint32_t child[2];
    uint32_t count;     // primitives below
    float cost;         // SAH cost of the subtree as emitted (half areas, unnormalised)
    uint32_t out_size;  // nodes this subtree becomes in the output
    uint16_t height;    // inner nodes on its longest path, as emitted
    uint8_t flags;      // kCollapsed, kRebuild
    uint8_t unused;
};
static_assert(sizeof(RawNode) == 48);
inline constexpr uint8_t kCollapsed = 1;  // emitted as one leaf
inline constexpr uint8_t kRebuild = 2;    // emitted as a balanced tree (depth limit)

// Morton codes of the triangles' box centres inside the bounds of those
// centres, and the identity order 0..n-1, ready for radix_sort_pairs.
// uint32_t keys get 30-bit codes, uint64_t keys 63-bit codes.
void compute_morton_codes(std::span<const Triangle> triangles, std::vector<uint32_t>& keys,
                          std::vector<uint32_t>& order);
void compute_morton_codes(std::span<const Triangle> triangles, std::vector<uint64_t>& keys,
                          std::vector<uint32_t>& order);

class RawTree {
public:
    RawTree(std::span<const Triangle> triangles, const BvhBuildConfig& config);

    // Sorts the triangles by the Morton codes of their box centres inside the
    // bounds of those centres (30-bit codes for uint32_t keys, 63-bit codes
    // for uint64_t keys; stable, so equal codes stay in triangle order), and
    // fills `order` and `boxes` in that order. `keys` receives the sorted
    // codes. The same result as compute_morton_codes, radix_sort_pairs and
    // set_order, with each triangle's box computed once. *code_ms (when not
    // null) receives the milliseconds spent before the sort (boxes, bounds, codes).
    void sort_by_morton_codes(Buffer<uint32_t>& keys, double* code_ms = nullptr);
    void sort_by_morton_codes(Buffer<uint64_t>& keys, double* code_ms = nullptr);

    // Takes the Morton order (sorted position -> triangle) and gathers the
    // triangles' boxes into it.
    void set_order(std::vector<uint32_t>&& order);
    // Leaf runs longer than one primitive (HLBVH2): sizes per first position.
    void enable_leaf_runs();
    void set_leaf_run(uint32_t first, uint32_t count) { leaf_run_[first] = static_cast<uint8_t>(count); }

    // Sets node `index`'s children and derives its box, count, cost and
    // collapse decision from theirs (which must be final already).
    void finalize(uint32_t index, uint32_t left, uint32_t right) {
        if (leaf_runs_) {
            finalize_impl<true>(index, left, right);
        } else {
            finalize_impl<false>(index, left, right);
        }
    }
    void finalize(uint32_t index) { finalize(index, nodes[index].child[0], nodes[index].child[1]); }
    // The same for trees without leaf runs (every leaf one primitive).
    void finalize_unit_leaves(uint32_t index, uint32_t left, uint32_t right) {
        finalize_impl<false>(index, left, right);
    }

    [[nodiscard, gnu::always_inline]] Box3f bounds(uint32_t ref) const {
        if (!is_leaf_ref(ref)) return nodes[ref].box;
        const uint32_t first = ref & ~kLeafRef;
        Box3f box = boxes[first];
        if (leaf_runs_) {
            for (uint32_t i = 1; i < leaf_run_[first]; ++i) box = box_union(box, boxes[first + i]);
        }
        return box;
    }
    [[nodiscard, gnu::always_inline]] uint32_t count(uint32_t ref) const {
        if (!is_leaf_ref(ref)) return nodes[ref].count;
        return leaf_runs_ ? leaf_run_[ref & ~kLeafRef] : 1u;
    }

    // The canonical BVH of the subtree at `root`.
    [[nodiscard]] Bvh emit(uint32_t root);
    // The same for trees whose leaves, left to right, are the sorted
    // positions 0, 1, 2, ... in order (LBVH): the primitive order is
    // then `order` itself and moves into the BVH; the tree is spent.
    [[nodiscard]] Bvh emit_in_order(uint32_t root);

    uint32_t size() const { return static_cast<uint32_t>(order.size()); }

    std::span<const Triangle> triangles;
    std::vector<uint32_t> order;  // sorted position -> triangle index
    Buffer<Box3f> boxes;          // sorted position -> triangle box
    std::vector<RawNode> nodes;

private:
    // A child's values in the shared emission's terms (raw_tree_emit_steps.h),
    // so the host and the device emission compute nodes with the same code.
    template <bool kLeafRuns>
    [[nodiscard, gnu::always_inline]] raw_emit::NodeInfo info(uint32_t ref) const {
        raw_emit::NodeInfo info;
        if (is_leaf_ref(ref)) {
            const uint32_t first = ref & ~kLeafRef;
            Box3f box = boxes[first];
            uint32_t n = 1;
            if constexpr (kLeafRuns) {
                n = leaf_run_[first];
                for (uint32_t i = 1; i < n; ++i) box = box_union(box, boxes[first + i]);
            }
            info.box = box;
            info.count = n;
            info.cost = raw_emit::leaf_cost(costs_, box, n);
            info.out_size = 1;
            info.height = 0;
            return info;
        }
        const RawNode& node = nodes[ref];
        info.box = node.box;
        info.count = node.count;
        info.cost = node.cost;
        info.out_size = node.out_size;
        info.height = static_cast<uint32_t>(node.height) << 1;
        return info;
    }
    // Karras 2013-style collapse: one leaf where the SAH prefers it (raw_emit::combine).
    template <bool kLeafRuns>
    [[gnu::always_inline]] void finalize_impl(uint32_t index, uint32_t left, uint32_t right) {
        const raw_emit::NodeInfo result = raw_emit::combine(costs_, info<kLeafRuns>(left), info<kLeafRuns>(right));
        RawNode& node = nodes[index];
        node.child[0] = left;
        node.child[1] = right;
        node.box = result.box;
        node.count = result.count;
        node.cost = result.cost;
        node.out_size = result.out_size;
        node.height = static_cast<uint16_t>(std::min<uint32_t>(raw_emit::info_height(result), 0xffff));
        node.flags = raw_emit::info_collapsed(result) ? kCollapsed : 0;
    }
    // Hidden: called only inside the library, so the (recursive) calls skip the PLT.
#define RF_MORTON_INTERNAL [[gnu::visibility("hidden")]]
    template <class Key>
    RF_MORTON_INTERNAL void sort_impl(Buffer<Key>& keys, double* code_ms);
    RF_MORTON_INTERNAL Bvh emit_impl(uint32_t root, bool in_order);
    RF_MORTON_INTERNAL void plan_depth(uint32_t index, int depth);
    template <bool kInOrder>
    RF_MORTON_INTERNAL void emit_node(Bvh& bvh, uint32_t ref, uint32_t at, uint32_t child_base, uint32_t slot) const;
    RF_MORTON_INTERNAL void gather_positions(uint32_t ref, std::vector<uint32_t>& positions) const;
    template <bool kInOrder>
    RF_MORTON_INTERNAL Box3f emit_balanced(Bvh& bvh, std::span<const uint32_t> positions, uint32_t at,
                                           uint32_t child_base, uint32_t slot) const;
    [[nodiscard]] RF_MORTON_INTERNAL uint32_t balanced_size(uint32_t count) const;
#undef RF_MORTON_INTERNAL

    uint32_t max_leaf_size_;
    raw_emit::Costs costs_;
    bool leaf_runs_ = false;   // false: every leaf run is one primitive
    Buffer<uint8_t> leaf_run_;
};

// Levels of halving until `count` primitives fit in leaves of `leaf_size`.
int balanced_levels(uint32_t count, uint32_t leaf_size);

}  // namespace rf::morton
