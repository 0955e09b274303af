// The skeleton of the top-down SAH builders (binned SAH, full-sweep SAH,
// SBVH), after the TopDownSahBuilder that serves the binned and sweep
// builders of madmann91/bvh (v2): one recursion over (node, references,
// depth) with the SAH's leaf decision and its fallbacks, child pairs taken
// from a shared counter, large subtrees built as parallel tasks, and the
// final copy of the tree from allocation (task) order into the canonical
// depth-first layout. A builder supplies how a node's references are held,
// how its best split is found and how the references are partitioned; it
// derives from TopDownSahBuilder<Builder, Task> (CRTP: every call resolves at
// compile time, no virtual call per node).
//
// Per node of n references, area A and the builder's best split (cost: the
// sum of area times references over both children):
//  - n == 1: a leaf;
//  - n <= max_leaf_size and (no valid split, or C_trav A + C_int cost >=
//    C_int A n): a leaf;
//  - a split after which halving could not reach leaves of max_leaf_size
//    within kBvhMaxDepth (median_levels) is dropped; without a split the
//    node is a leaf when n <= max_leaf_size, else halved at the object median.
//
// Parallelism: children of nodes over Builder::kParallelSubtreeSize
// references are built as tasks (parallel::invoke); the copy runs the two
// subtrees of large nodes as tasks too. Every decision depends only on a
// node's references, so the tree is the same for every thread count.
#pragma once

#include <atomic>
#include <bit>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>

#include "accel/bvh/builders/bvh_build_config.h"
#include "core/parallel.h"
#include "core/assert.h"
#include "core/huge_pages.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/memory_budget.h"

namespace rf::top_down {

// Levels of halving needed until `count` references fit in leaves of `leaf_size`.
inline int median_levels(uint64_t count, uint32_t leaf_size) {
    const uint64_t leaves = (count + leaf_size - 1) / leaf_size;
    return leaves <= 1 ? 0 : static_cast<int>(std::bit_width(leaves - 1));
}

// Whether a child of `count` references at depth + 1 can still reach leaves
// of `leaf_size` by halving within kBvhMaxDepth.
inline bool depth_allows(int depth, uint64_t count, uint32_t leaf_size) {
    return depth + 1 + median_levels(count, leaf_size) <= kBvhMaxDepth;
}

// Uninitialised array of plain data (budget-checked), hinted for huge pages when large.
template <class T>
std::unique_ptr<T[]> scratch_array(size_t count, std::string_view what) {
    static_assert(std::is_trivially_default_constructible_v<T>);
    checked_array_bytes(what, count, sizeof(T));
    std::unique_ptr<T[]> a(new T[count]);
    hint_huge_pages(a.get(), count * sizeof(T));
    return a;
}

// A node in allocation order; the layout of BvhNode, but plain data (arrays
// of it are not zero-filled). Inner: count == 0, children at first and first + 1.
struct ScratchNode {
    float lo[3], hi[3];
    uint32_t first, count;
    [[nodiscard]] bool is_leaf() const { return count != 0; }
    void set_bounds(const Box3f& b) {
        lo[0] = b.lo.x; lo[1] = b.lo.y; lo[2] = b.lo.z;
        hi[0] = b.hi.x; hi[1] = b.hi.y; hi[2] = b.hi.z;
    }
    [[nodiscard]] BvhNode to_node() const { return {{{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}}, first, count}; }
};
static_assert(sizeof(ScratchNode) == 32 && std::is_trivially_default_constructible_v<ScratchNode>);

// What a finished subtree hands back to its parent: nothing, unless the
// builder says otherwise (SBVH: the spare references it did not use).
struct NoCarry {
    NoCarry operator+(NoCarry) const { return {}; }
};

// Builder (the derived class; TopDownSahBuilder is its friend) provides:
//   Task: a node's references, with count() and bounds() (a Box3f);
//   Split find_split(Task&, int depth): its best split; Split has valid(),
//       cost() (the sum of area times references over both children) and
//       larger_child(count), the references of its larger side;
//   void partition(Task&, Split&, Task& left, Task& right): by a valid split;
//   void partition_at_median(Task&, Split&, Task& left, Task& right): halves
//       the references (the object median); both spend the split, which
//       stays in the recursion's frame while the children are built, so
//       they free what it holds;
//   uint32_t place_leaf(Task&): the first leaf slot of the task's references;
//   uint32_t slot_prim(uint32_t slot): the triangle in a leaf slot;
//   kName (memory-budget messages: "<kName>: scratch nodes"),
//   kParallelSubtreeSize (references of a node whose children become tasks),
//   kLeavesInPlace: true when the leaves of a subtree already take
//       consecutive slots, left subtree first (so the slots are final);
//       false has the copy renumber them depth-first;
//   with a Carry other than NoCarry: Carry leaf_carry(Task&) and
//       hand_over(Carry, Task& right): children built one after the other
//       pass what the left subtree handed back on to the right one.
template <class Builder, class Task, class Carry = NoCarry>
class TopDownSahBuilder {
protected:
    explicit TopDownSahBuilder(const BvhBuildConfig& config)
        : max_leaf_size_(static_cast<uint32_t>(config.max_leaf_size)), sah_(config.sah), progress_(config.progress) {}

    // Builds the tree over `root`, whose leaves hold at most `max_refs`
    // references in all, and returns it in the canonical layout.
    Bvh build_tree(Task& root, uint64_t max_refs) {
        const uint32_t root_count = root.count();
        const size_t max_nodes = 2 * max_refs - 1;  // every leaf holds at least one reference
        const std::string name(Builder::kName);
        nodes_ = scratch_array<ScratchNode>(max_nodes, name + ": scratch nodes");
        subtree_size_ = scratch_array<uint32_t>(max_nodes, name + ": subtree sizes");
        if constexpr (!Builder::kLeavesInPlace) {
            subtree_slots_ = scratch_array<uint32_t>(max_nodes, name + ": subtree slots");
        }
        next_node_.store(1, std::memory_order_relaxed);
        build_subtree(0, root, 0);
        if constexpr (Builder::kLeavesInPlace) {
            return emit(root_count);
        } else {
            return emit(subtree_slots_[0]);
        }
    }

    [[nodiscard]] uint32_t max_leaf_size() const { return max_leaf_size_; }

private:
    Builder& builder() { return static_cast<Builder&>(*this); }
    const Builder& builder() const { return static_cast<const Builder&>(*this); }

    enum class Cut { None, Split, Median };

    // Builds the subtree of nodes_[node] over `task`'s references.
    Carry build_subtree(uint32_t node, Task& task, int depth) {
        const uint32_t count = task.count();  // partitioning may free the task's references
        const Box3f bounds = task.bounds();
        nodes_[node].set_bounds(bounds);
        if (count <= 1) return make_leaf(node, task);
        auto split = builder().find_split(task, depth);
        const Cut cut = choose_cut(split, count, bounds, depth);
        if (cut == Cut::None) return make_leaf(node, task);
        Task left, right;
        if (cut == Cut::Split) {
            builder().partition(task, split, left, right);
        } else {
            builder().partition_at_median(task, split, left, right);
        }
        RF_ASSERT(depth < kBvhMaxDepth, "a top-down build past kBvhMaxDepth: the depth-limit fallback failed");
        RF_ASSERT(left.count() > 0 && right.count() > 0, "a split with an empty side");
        const uint32_t pair = next_node_.fetch_add(2, std::memory_order_relaxed);
        nodes_[node].first = pair;
        nodes_[node].count = 0;
        const Carry carry = build_children(pair, left, right, depth + 1, count);
        subtree_size_[node] = 1 + subtree_size_[pair] + subtree_size_[pair + 1];
        if constexpr (!Builder::kLeavesInPlace) {
            subtree_slots_[node] = subtree_slots_[pair] + subtree_slots_[pair + 1];
        }
        return carry;
    }

    // The leaf decision of the file comment for a node of two or more references.
    template <class Split>
    Cut choose_cut(const Split& split, uint32_t count, const Box3f& bounds, int depth) const {
        const float area = bounds.surface_area();
        const float leaf_cost = sah_.intersection * area * static_cast<float>(count);
        const float split_cost = sah_.traversal * area + sah_.intersection * split.cost();
        if (count <= max_leaf_size_ && (!split.valid() || split_cost >= leaf_cost)) return Cut::None;
        // A lopsided split deep in the tree could exceed kBvhMaxDepth; from
        // here on, halving still reaches leaves in time.
        if (split.valid() && depth_allows(depth, split.larger_child(count), max_leaf_size_)) return Cut::Split;
        return count <= max_leaf_size_ ? Cut::None : Cut::Median;
    }

    Carry build_children(uint32_t pair, Task& left, Task& right, int depth, uint32_t count) {
        if (count > Builder::kParallelSubtreeSize) {
            Carry left_carry{}, right_carry{};
            parallel::invoke([&] { left_carry = build_subtree(pair, left, depth); },
                             [&] { right_carry = build_subtree(pair + 1, right, depth); });
            return left_carry + right_carry;
        }
        const Carry left_carry = build_subtree(pair, left, depth);
        if constexpr (!std::is_same_v<Carry, NoCarry>) builder().hand_over(left_carry, right);
        return build_subtree(pair + 1, right, depth);
    }

    Carry make_leaf(uint32_t node, Task& task) {
        const uint32_t count = task.count();
        nodes_[node].first = builder().place_leaf(task);
        nodes_[node].count = count;
        subtree_size_[node] = 1;
        if (progress_) progress_->add(count);
        if constexpr (!Builder::kLeavesInPlace) subtree_slots_[node] = count;
        if constexpr (std::is_same_v<Carry, NoCarry>) {
            return {};
        } else {
            return builder().leaf_carry(task);
        }
    }

    // The canonical layout: nodes copied depth-first (a node's children
    // pair, then the left subtree's descendants, then the right's), and the
    // triangles of the `slot_count` leaf slots.
    Bvh emit(uint32_t slot_count) {
        Bvh bvh;
        auto copy_nodes = [&] {
            const uint32_t node_count = subtree_size_[0];
            checked_array_bytes("BVH nodes", node_count, sizeof(BvhNode));
            bvh.nodes.reserve(node_count);
            hint_huge_pages(bvh.nodes.data(), size_t{node_count} * sizeof(BvhNode));
            bvh.nodes.resize(node_count);
            bvh.nodes[0] = place(0, 0, bvh);
            copy_descendants(bvh, 0, 0, 1, 0);
        };
        if constexpr (Builder::kLeavesInPlace) {
            parallel::invoke(copy_nodes, [&] {
                budgeted_resize(bvh.prim_indices, slot_count, "BVH primitive indices");
                parallel::for_range(0u, slot_count, kCopyGrainSize, [&](uint32_t lo, uint32_t hi) {
                    for (uint32_t i = lo; i != hi; ++i) bvh.prim_indices[i] = builder().slot_prim(i);
                });
            });
        } else {
            budgeted_resize(bvh.prim_indices, slot_count, "BVH primitive indices");
            copy_nodes();
        }
        return bvh;
    }

    // nodes_[from] as an output node; renumbering, a leaf gets `slot` as its
    // first slot and its triangles are written there.
    BvhNode place(uint32_t from, [[maybe_unused]] uint32_t slot, [[maybe_unused]] Bvh& bvh) const {
        BvhNode out = nodes_[from].to_node();
        if constexpr (!Builder::kLeavesInPlace) {
            if (out.is_leaf()) {
                for (uint32_t i = 0; i < out.count; ++i) {
                    bvh.prim_indices[slot + i] = builder().slot_prim(out.first + i);
                }
                out.first = slot;
            }
        }
        return out;
    }

    // Writes the descendants of nodes_[from] (copied to bvh.nodes[at]) into
    // bvh.nodes[base, base + subtree size - 1), their leaves' slots (when
    // renumbering) from `slot` on.
    void copy_descendants(Bvh& bvh, uint32_t from, uint32_t at, uint32_t base, uint32_t slot) const {
        if (nodes_[from].is_leaf()) return;
        const uint32_t left = nodes_[from].first;
        uint32_t right_slot = slot;
        if constexpr (!Builder::kLeavesInPlace) right_slot += subtree_slots_[left];
        bvh.nodes[at].first = base;
        bvh.nodes[base] = place(left, slot, bvh);
        bvh.nodes[base + 1] = place(left + 1, right_slot, bvh);
        const uint32_t right_base = base + 2 + (subtree_size_[left] - 1);
        if (subtree_size_[from] > kParallelCopySize) {
            parallel::invoke([&] { copy_descendants(bvh, left, base, base + 2, slot); },
                             [&] { copy_descendants(bvh, left + 1, base + 1, right_base, right_slot); });
        } else {
            copy_descendants(bvh, left, base, base + 2, slot);
            copy_descendants(bvh, left + 1, base + 1, right_base, right_slot);
        }
    }

    static constexpr uint32_t kParallelCopySize = 4096;  // nodes per subtree to copy in parallel
    static constexpr uint32_t kCopyGrainSize = 16 * 1024;

    uint32_t max_leaf_size_;
    SahCosts sah_;
    ProgressMeter* progress_;
    std::unique_ptr<ScratchNode[]> nodes_;       // in allocation order
    std::unique_ptr<uint32_t[]> subtree_size_;   // per node: nodes in its subtree
    std::unique_ptr<uint32_t[]> subtree_slots_;  // per node: leaf slots in its subtree (renumbering only)
    std::atomic<uint32_t> next_node_{1};
};

}  // namespace rf::top_down
