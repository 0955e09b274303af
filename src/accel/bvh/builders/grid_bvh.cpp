// GridBvh and GridBvhSplit builders (Garanzha 2014, dissertation ch. 4,
// §4.1-4.4), on the CPU with TBB.
//
// 1. References: one per triangle, or partial triangles (§4.4, see
//    grid_bvh_partial_triangles.cpp).
// 2. Grid0 and its levels of detail (§4.2, see grid_bvh_sparse_grid.cpp).
// 3. EmitHierarchy (Algorithm 4.1): breadth-first, one queue of split tasks
//    per tree level processed in parallel. A task is (node, grid level, IBB =
//    integer box of cells). Along each axis its IBB (at most 8 cells wide,
//    MaxUseRes) is cut into 8 bins by 7 planes; each bin gathers the
//    reference count and integer box of its non-empty cells, and the plane
//    with the least SA(bboxL)*numL + SA(bboxR)*numR wins. The children's
//    IBBs are the tight boxes of their non-empty cells. When the longest
//    extent of an IBB is at most MaxUseRes / 2 the task refines to the next
//    finer grid (coordinates doubled). Areas use the cells' world sizes, as
//    Grid0 cells follow the scene box and need not be cubic. A task becomes a
//    leaf at <= max_leaf_size references or when its IBB is one Grid0 cell.
// 4. Leaf finishing. The partition is only recorded by the IBBs (gap in §8:
//    a leaf spanning several cells has no contiguous segment of the sorted
//    references). Each reference finds its leaf by descending the hierarchy
//    with its Grid0 cell, and references are grouped by leaf (a counting
//    sort). Parts of one triangle in one leaf are merged into one reference
//    (union box). Leaves with more than max_leaf_size references (a crowded
//    Grid0 cell, or the depth limit) are split further by a small binned SAH
//    over reference centroids (8 bins), instead of the dissertation's trivial
//    cut of the list, so every leaf obeys the limit; like the binned builder,
//    a leaf of up to max_leaf_size references is also split where the SAH
//    (SahCosts C_trav, C_int) says a split is cheaper (the dissertation stops
//    at <= 4 references; on the bunny, Sponza and Conference that cost 2-4%
//    SAH at C_trav = C_int = 1).
// 5. Canonical emission: subtree sizes and boxes bottom-up per tree level
//    (levelOffset of Algorithm 4.1), then positions top-down, giving the
//    depth-first layout of rf::Bvh.
//
// The per-task step of 3 (process_task), the cell keys and the sparse-grid
// reads are grid_bvh_steps.h's; the per-leaf finishing of 4 (for leaves of
// up to kDeviceFinishRefs references, the ones one device thread can take)
// and the per-node steps of 5 are grid_bvh_finish_steps.h's: both shared
// with the CUDA builder (backend/cuda/grid_bvh_build.cu), which hands its
// hierarchy to steps 4-5 here through emit_grid_bvh_hierarchy
// (grid_bvh_emit.h) only when a leaf is too large for one thread. Larger
// leaves are built here recursively (their halves in parallel) over the same
// per-node step, with the same result as the shared iterative build.
//
// Depth: a grid split at depth d is taken only if d + 1 + the halving levels
// of its larger side stay within kBvhMaxDepth; otherwise the task becomes a
// large leaf whose finishing falls back to median splits in time. Every
// decision depends on the input alone (fixed block sizes, ordered queues), so
// the tree is the same for every thread count.
#include "accel/bvh/builders/grid_bvh.h"
#include "accel/bvh/builders/grid_bvh_emit.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/grid_bvh_finish_steps.h"
#include "accel/bvh/builders/grid_bvh_partial_triangles.h"
#include "accel/bvh/builders/grid_bvh_sparse_grid.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using gridbvh::CellBox;
using gridbvh::EmitPosition;
using gridbvh::FinishOptions;
using gridbvh::GridFrame;
using gridbvh::GridRef;
using gridbvh::kDeviceFinishRefs;
using gridbvh::kLeafBit;
using gridbvh::LeafSummary;
using gridbvh::LocalSplit;
using gridbvh::NodeRegion;
using gridbvh::SparseGrid;
using gridbvh::SplitTask;
using gridbvh::SubtreeSize;
using gridbvh::TaskOutcome;
constexpr uint32_t kParallelFinishSize = 4096;  // references per large-leaf subtree to build as two tasks

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// Box growth with std::min/max, which compile to single instructions (the
// NaN-aware fminf/fmaxf behind rf::min/max are library calls).
inline Vec3f vmin(const Vec3f& a, const Vec3f& b) {
    return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3f vmax(const Vec3f& a, const Vec3f& b) {
    return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}

// The subtree of a finished leaf that is more than one node, in canonical
// relative layout (node 0 its root; inner `first` is a local node index,
// leaf `first` a local slot). Its triangles end up in leaf_prims_ at the
// leaf's reference range, like those of a single-node leaf; `prims` only
// collects them while a large leaf is built recursively.
struct LocalTree {
    std::vector<BvhNode> nodes;
    std::vector<uint32_t> prims;
};

// The median split's sort: the shared insertion sort for short ranges,
// std::sort for long ones; median_before is a total order, so both give the
// same sequence.
struct SortOnAxis {
    void operator()(GridRef* refs, uint32_t count, int axis) const {
        if (count <= kDeviceFinishRefs) return gridbvh::InsertionSortOnAxis{}(refs, count, axis);
        std::sort(refs, refs + count,
                  [axis](const GridRef& a, const GridRef& b) { return gridbvh::median_before(a, b, axis); });
    }
};

class GridBvhBuilder {
public:
    GridBvhBuilder(std::span<const Triangle> triangles, const BvhBuildConfig& config, const GridBvhOptions& grid_bvh,
                   bool partial_triangles, GridBvhStages& stages)
        : triangles_(triangles),
          max_leaf_size_(uint32_t(std::max(1, config.max_leaf_size))),
          traversal_cost_(config.sah.traversal),
          intersection_cost_(config.sah.intersection),
          split_budget_(grid_bvh.split_budget),
          partial_triangles_(partial_triangles),
          stages_(stages) {}

    Bvh build() {
        const auto total_start = std::chrono::steady_clock::now();
        Bvh bvh;
        stages_.triangles = triangles_.size();
        checked_index_count("GridBvh triangles", triangles_.size());
        if (triangles_.empty()) return bvh;

        // §4.4: references, then partial triangles.
        auto start = std::chrono::steady_clock::now();
        refs_ = gridbvh::make_triangle_refs(triangles_);
        const Box3f scene = parallel::reduce(
            size_t{0}, refs_.size(), size_t{16 * 1024}, Box3f{},
            [&](size_t lo, size_t hi, Box3f acc) {
                for (size_t i = lo; i < hi; ++i) acc = {vmin(acc.lo, refs_[i].lo), vmax(acc.hi, refs_[i].hi)};
                return acc;
            },
            [](Box3f a, const Box3f& b) { return Box3f{vmin(a.lo, b.lo), vmax(a.hi, b.hi)}; });
        const GridFrame frame(scene);
        frame_ = &frame;
        if (partial_triangles_) {
            refs_ = gridbvh::split_into_partial_triangles(triangles_, std::move(refs_), frame, split_budget_);
        }
        checked_index_count("GridBvh references", refs_.size());
        stages_.references = refs_.size();
        stages_.partial_triangles_ms = ms_since(start);

        // §4.2: Grid0 and the coarser levels.
        SparseGrid::BuildTimes grid_times;
        grid_.build(refs_, frame, &grid_times);
        stages_.sort_ms = grid_times.sort_ms;
        stages_.grid0_ms = grid_times.grid0_ms;
        stages_.coarse_levels_ms = grid_times.coarse_ms;
        stages_.occupied_top_cells = grid_.occupied_top_cells();
        stages_.grid_bytes = grid_.memory_bytes();

        start = std::chrono::steady_clock::now();
        emit_hierarchy();
        stages_.hierarchy_ms = ms_since(start);
        stages_.hierarchy_leaves = leaves_.size();

        return finish_and_emit(std::move(bvh), total_start);
    }

    // Leaf finishing and emission of a hierarchy built elsewhere (the device).
    Bvh emit(GridHierarchy&& h) {
        const auto total_start = std::chrono::steady_clock::now();
        Bvh bvh;
        stages_.triangles = triangles_.size();
        checked_index_count("GridBvh triangles", triangles_.size());
        if (triangles_.empty()) return bvh;
        check_hierarchy(h);
        refs_ = std::move(h.refs);
        frame_ = &h.frame;
        hnodes_ = std::move(h.hnodes);
        regions_ = std::move(h.regions);
        leaves_ = std::move(h.leaves);
        level_offset_ = std::move(h.level_offset);
        leaf_begin_ = std::move(h.leaf_begin);
        leaf_refs_ = std::move(h.leaf_refs);
        stages_.references = refs_.size();
        stages_.hierarchy_leaves = leaves_.size();
        return finish_and_emit(std::move(bvh), total_start);
    }

    // The stages both paths share: leaf finishing and canonical emission.
    Bvh finish_and_emit(Bvh bvh, std::chrono::steady_clock::time_point total_start) {
        auto start = std::chrono::steady_clock::now();
        finish_leaves();
        stages_.leaf_finish_ms = ms_since(start);
        start = std::chrono::steady_clock::now();
        emit_canonical(bvh);
        stages_.emission_ms = ms_since(start);
        stages_.total_ms = ms_since(total_start);
        frame_ = nullptr;
        return bvh;
    }

private:
    // What emit() relies on: children inside the next level, leaves in range.
    void check_hierarchy(const GridHierarchy& h) const {
        const size_t nodes = h.hnodes.size();
        if (h.refs.empty() || nodes == 0 || h.regions.size() != nodes || h.level_offset.size() < 2 ||
            h.level_offset.front() != 0 || h.level_offset.back() != nodes) {
            throw Error("GridBvh hierarchy: malformed node arrays");
        }
        if (!h.leaf_begin.empty()) {
            bool bad = h.leaf_begin.size() != h.leaves.size() + 1 || h.leaf_refs.size() != h.refs.size() ||
                       h.leaf_begin.front() != 0 || h.leaf_begin.back() != h.refs.size();
            for (size_t l = 0; !bad && l + 1 < h.leaf_begin.size(); ++l) bad = h.leaf_begin[l] > h.leaf_begin[l + 1];
            for (size_t i = 0; !bad && i < h.leaf_refs.size(); ++i) bad = h.leaf_refs[i] >= h.refs.size();
            if (bad) throw Error("GridBvh hierarchy: malformed leaf groups");
        }
        for (size_t l = 0; l + 1 < h.level_offset.size(); ++l) {
            const uint32_t end = h.level_offset[l + 1];
            if (h.level_offset[l] >= end) throw Error("GridBvh hierarchy: empty tree level");
            for (uint32_t n = h.level_offset[l]; n < end; ++n) {
                const uint32_t v = h.hnodes[n];
                const bool bad = (v & kLeafBit) ? (v & ~kLeafBit) >= h.leaves.size()
                                                : v < end || l + 2 >= h.level_offset.size() ||
                                                      size_t{v} + 1 >= h.level_offset[l + 2];
                if (bad) throw Error("GridBvh hierarchy: node " + std::to_string(n) + " links outside its child level");
            }
        }
    }

    // §4.3, Algorithm 4.1: level-by-level split queues.
    void emit_hierarchy() {
        std::vector<SplitTask> queue{gridbvh::root_task(uint32_t(refs_.size()))};
        std::vector<SplitTask> next;
        std::vector<TaskOutcome> outcomes;
        hnodes_.assign(1, 0);
        regions_.assign(1, NodeRegion{queue.front().box, queue.front().level});
        level_offset_.clear();
        leaves_.clear();
        while (!queue.empty()) {
            level_offset_.push_back(queue.front().node);
            outcomes.resize(queue.size());
            parallel::for_range(size_t{0}, queue.size(), size_t{64}, [&](size_t lo, size_t hi) {
                for (size_t i = lo; i < hi; ++i) outcomes[i] = process(queue[i]);
            });
            // Compaction in queue order: children get consecutive node pairs.
            next.clear();
            for (const TaskOutcome& o : outcomes) {
                const uint32_t node = o.left.node;
                if (!o.split) {
                    hnodes_[node] = kLeafBit | uint32_t(leaves_.size());
                    leaves_.push_back(o.left);
                    continue;
                }
                const uint32_t pair = uint32_t(hnodes_.size());
                hnodes_[node] = pair;
                budgeted_push_back(hnodes_, 0u, "GridBvh: hierarchy nodes");
                budgeted_push_back(hnodes_, 0u, "GridBvh: hierarchy nodes");
                budgeted_push_back(regions_, NodeRegion{o.left.box, o.left.level}, "GridBvh: hierarchy nodes");
                budgeted_push_back(regions_, NodeRegion{o.right.box, o.right.level}, "GridBvh: hierarchy nodes");
                SplitTask left = o.left, right = o.right;
                left.node = pair;
                right.node = pair + 1;
                next.push_back(left);
                next.push_back(right);
            }
            queue.swap(next);
        }
        level_offset_.push_back(uint32_t(hnodes_.size()));
    }

    // One split task (Fig. 4.3): the shared step, scanning on this thread.
    TaskOutcome process(const SplitTask& task) const {
        const gridbvh::SparseGridView view = grid_.view();
        return gridbvh::process_task(task, max_leaf_size_, *frame_, gridbvh::SerialScan{&view});
    }

    // The reference shuffling of §4.3 ("applied at leaf generation"): each
    // reference finds its leaf by descending the hierarchy with its Grid0
    // cell (sibling IBBs are disjoint), references are grouped by leaf, and
    // each leaf is finished.
    void finish_leaves() {
        const uint32_t n = uint32_t(refs_.size());
        const uint32_t leaf_count = uint32_t(leaves_.size());
        if (leaf_begin_.empty()) group_by_leaf();  // else grouped already (by the device)
        trees_.clear();
        trees_.resize(leaf_count);
        summaries_.assign(leaf_count, LeafSummary{});
        budgeted_resize(leaf_prims_, n, "GridBvh: leaf triangles");
        const FinishOptions options = finish_options();
        std::atomic<size_t> large{0};
        parallel::for_range(0u, leaf_count, 64u, [&](uint32_t lo, uint32_t hi) {
            std::vector<GridRef> refs, scratch;
            BvhNode small_tree[2 * kDeviceFinishRefs];
            for (uint32_t l = lo; l < hi; ++l) {
                const uint32_t begin = leaf_begin_[l], count = leaf_begin_[l + 1] - begin;
                uint32_t* prims = leaf_prims_.data() + begin;
                LeafSummary s;
                if (count <= kDeviceFinishRefs) {
                    // What one device thread runs for this leaf.
                    s = gridbvh::finish_small_leaf(refs_.data(), leaf_refs_.data() + begin, count, leaves_[l].depth,
                                                   options, small_tree, prims);
                    if (s.node_count > 1) trees_[l].nodes.assign(small_tree, small_tree + s.node_count);
                } else {
                    s = finish_large_leaf(l, refs, scratch, prims);
                }
                if (s.prim_count > max_leaf_size_) large.fetch_add(1, std::memory_order_relaxed);
                summaries_[l] = s;
            }
        });
        stages_.large_leaves = large.load();
    }

    FinishOptions finish_options() const { return FinishOptions{max_leaf_size_, traversal_cost_, intersection_cost_}; }

    // A leaf of more than kDeviceFinishRefs references: the same steps as
    // finish_small_leaf, in growable buffers, the tree built recursively.
    LeafSummary finish_large_leaf(uint32_t l, std::vector<GridRef>& refs, std::vector<GridRef>& scratch,
                                  uint32_t* prims) {
        // Reference order within a leaf is fixed by sorting, whatever the
        // order the grouping ran in.
        uint32_t* begin = leaf_refs_.data() + leaf_begin_[l];
        uint32_t* end = leaf_refs_.data() + leaf_begin_[l + 1];
        std::sort(begin, end);
        refs.clear();
        for (const uint32_t* r = begin; r != end; ++r) refs.push_back(refs_[*r]);
        const uint32_t count = gridbvh::merge_parts(refs.data(), uint32_t(refs.size()));
        refs.resize(count);
        scratch.resize(count);
        const FinishOptions options = finish_options();
        if (count <= max_leaf_size_ && gridbvh::keep_as_leaf(refs.data(), count, options, scratch.data())) {
            return gridbvh::single_leaf(refs.data(), count, prims);
        }
        LocalTree& tree = trees_[l];
        tree.nodes.reserve(2 * size_t{count} - 1);
        tree.prims.reserve(count);
        tree.nodes.resize(1);
        build_local(tree, refs.data(), scratch.data(), count, leaves_[l].depth, 0);
        std::copy(tree.prims.begin(), tree.prims.end(), prims);
        tree.prims = {};
        return LeafSummary{tree.nodes[0].bounds, uint32_t(tree.nodes.size()), count};
    }

    // Each reference's leaf (descent with its Grid0 cell), then the
    // references grouped by leaf (a counting sort).
    void group_by_leaf() {
        const uint32_t n = uint32_t(refs_.size());
        const uint32_t leaf_count = uint32_t(leaves_.size());
        std::vector<uint32_t> leaf_of, cursor;
        budgeted_resize(leaf_of, n, "GridBvh: leaf of reference");
        budgeted_resize(cursor, size_t{leaf_count} + 1, "GridBvh: leaf ranges");
        parallel::for_range(0u, n, 4096u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i < hi; ++i) {
                const uint32_t leaf = gridbvh::leaf_of_reference(hnodes_.data(), regions_.data(), *frame_, refs_[i]);
                leaf_of[i] = leaf;
                std::atomic_ref<uint32_t>(cursor[leaf]).fetch_add(1, std::memory_order_relaxed);
            }
        });
        leaf_begin_.resize(size_t{leaf_count} + 1);
        uint32_t running = 0;
        for (uint32_t l = 0; l <= leaf_count; ++l) {
            leaf_begin_[l] = running;
            if (l < leaf_count) running += cursor[l];
            cursor[l] = leaf_begin_[l];
        }
        budgeted_resize(leaf_refs_, n, "GridBvh: leaf references");
        parallel::for_range(0u, n, 4096u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i < hi; ++i) {
                leaf_refs_[std::atomic_ref<uint32_t>(cursor[leaf_of[i]]).fetch_add(1, std::memory_order_relaxed)] = i;
            }
        });
    }

    // Builds tree.nodes[node] over refs[0, count) at tree depth `depth` by
    // the shared per-node step (gridbvh::split_local_node), in the order of
    // gridbvh::build_local_tree. Large ranges build their halves as parallel
    // tasks into separate trees, joined in canonical order. `scratch` runs
    // alongside `refs` (disjoint for the two halves).
    void build_local(LocalTree& tree, GridRef* refs, GridRef* scratch, uint32_t count, int depth, uint32_t node) const {
        const LocalSplit s = gridbvh::split_local_node(refs, count, depth, finish_options(), scratch, SortOnAxis{});
        tree.nodes[node].bounds = s.bounds;
        if (s.leaf) {
            tree.nodes[node].first = uint32_t(tree.prims.size());
            tree.nodes[node].count = count;
            for (uint32_t i = 0; i < count; ++i) tree.prims.push_back(refs[i].prim);
            return;
        }
        const uint32_t mid = s.mid;
        if (count > kParallelFinishSize) {
            LocalTree left, right;
            left.nodes.resize(1);
            right.nodes.resize(1);
            parallel::invoke([&] { build_local(left, refs, scratch, mid, depth + 1, 0); },
                             [&] { build_local(right, refs + mid, scratch + mid, count - mid, depth + 1, 0); });
            append_children(tree, node, left, right);
            return;
        }
        const uint32_t pair = uint32_t(tree.nodes.size());
        tree.nodes.resize(pair + 2);
        tree.nodes[node].first = pair;
        tree.nodes[node].count = 0;
        build_local(tree, refs, scratch, mid, depth + 1, pair);
        build_local(tree, refs + mid, scratch + mid, count - mid, depth + 1, pair + 1);
    }

    // Appends two separately built subtrees as the children of tree.nodes[node]:
    // the pair, then the left one's descendants, then the right one's.
    static void append_children(LocalTree& tree, uint32_t node, const LocalTree& left, const LocalTree& right) {
        const uint32_t base = uint32_t(tree.nodes.size());
        const uint32_t prim_base = uint32_t(tree.prims.size());
        const uint32_t left_size = uint32_t(left.nodes.size());
        tree.nodes[node].first = base;
        tree.nodes[node].count = 0;
        tree.nodes.resize(size_t{base} + left.nodes.size() + right.nodes.size());
        auto place = [&](const LocalTree& sub, uint32_t root_at, uint32_t desc_offset, uint32_t prim_offset) {
            for (size_t j = 0; j < sub.nodes.size(); ++j) {
                BvhNode n = sub.nodes[j];
                n.first = n.is_leaf() ? n.first + prim_offset : n.first + desc_offset;
                tree.nodes[j == 0 ? root_at : j + desc_offset] = n;
            }
        };
        // Local index j >= 1 of the left tree lands at base + 1 + j, of the right at base + left_size + j.
        place(left, base, base + 1, prim_base);
        place(right, base + 1, base + left_size, prim_base + uint32_t(left.prims.size()));
        tree.prims.insert(tree.prims.end(), left.prims.begin(), left.prims.end());
        tree.prims.insert(tree.prims.end(), right.prims.begin(), right.prims.end());
    }

    // Sizes and boxes bottom-up per tree level, positions top-down, then the
    // copy: the shared per-node steps, one level at a time as on the device.
    void emit_canonical(Bvh& bvh) const {
        const size_t count = hnodes_.size();
        std::vector<SubtreeSize> size(count);
        std::vector<Box3f> box(count);
        std::vector<EmitPosition> at(count);
        const size_t levels = level_offset_.size() - 1;
        for (size_t l = levels; l-- > 0;) {
            parallel::for_range(level_offset_[l], level_offset_[l + 1], 1024u, [&](uint32_t lo, uint32_t hi) {
                for (uint32_t h = lo; h < hi; ++h) {
                    gridbvh::emit_size_and_box(h, hnodes_.data(), summaries_.data(), size.data(), box.data());
                }
            });
        }
        at[0] = gridbvh::root_position();
        for (size_t l = 0; l < levels; ++l) {
            parallel::for_range(level_offset_[l], level_offset_[l + 1], 1024u, [&](uint32_t lo, uint32_t hi) {
                for (uint32_t h = lo; h < hi; ++h) gridbvh::emit_positions(h, hnodes_.data(), size.data(), at.data());
            });
        }
        budgeted_resize(bvh.nodes, size[0].nodes, "BVH nodes");
        budgeted_resize(bvh.prim_indices, size[0].prims, "BVH primitive indices");
        parallel::for_range(0u, uint32_t(count), 1024u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t h = lo; h < hi; ++h) {
                const uint32_t first = hnodes_[h];
                if (!(first & kLeafBit)) {
                    gridbvh::emit_inner_node(box[h], at[h], bvh.nodes.data());
                    continue;
                }
                const uint32_t leaf = first & ~kLeafBit;
                gridbvh::emit_leaf(summaries_[leaf], trees_[leaf].nodes.data(), leaf_prims_.data() + leaf_begin_[leaf],
                                   at[h], bvh.nodes.data(), bvh.prim_indices.data());
            }
        });
    }

    std::span<const Triangle> triangles_;
    uint32_t max_leaf_size_;
    float traversal_cost_;
    float intersection_cost_;
    float split_budget_;
    bool partial_triangles_;
    GridBvhStages& stages_;

    const GridFrame* frame_ = nullptr;
    std::vector<GridRef> refs_;
    SparseGrid grid_;
    std::vector<uint32_t> hnodes_;        // per hierarchy node: first child, or kLeafBit | leaf index
    std::vector<uint32_t> level_offset_;  // first hierarchy node of each tree level, plus the end
    std::vector<SplitTask> leaves_;       // leaf tasks in creation order
    std::vector<NodeRegion> regions_;     // per hierarchy node: its IBB at creation
    std::vector<uint32_t> leaf_begin_;    // per leaf task, plus an end: its range in leaf_refs_
    std::vector<uint32_t> leaf_refs_;     // reference indices grouped by leaf
    std::vector<uint32_t> leaf_prims_;    // per leaf task, at its range in leaf_refs_: its triangles in leaf order
    std::vector<LeafSummary> summaries_;  // per leaf task: box, node and triangle counts
    std::vector<LocalTree> trees_;        // per leaf task: its subtree when more than one node
};

}  // namespace

Bvh build_grid_bvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, const GridBvhOptions& grid_bvh,
                   bool partial_triangles, GridBvhStages* stages) {
    GridBvhStages local;
    GridBvhBuilder builder(triangles, config, grid_bvh, partial_triangles, stages ? *stages : local);
    return builder.build();
}

Bvh emit_grid_bvh_hierarchy(std::span<const Triangle> triangles, const BvhBuildConfig& config, bool partial_triangles,
                            GridHierarchy&& hierarchy, GridBvhStages* stages) {
    GridBvhStages local;
    // The references come split already: the split budget is not read.
    GridBvhBuilder builder(triangles, config, GridBvhOptions{}, partial_triangles, stages ? *stages : local);
    return builder.emit(std::move(hierarchy));
}

Bvh build_grid_bvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, const GridBvhOptions& grid_bvh,
                   bool partial_triangles) {
    return build_grid_bvh(triangles, config, grid_bvh, partial_triangles, nullptr);
}

}  // namespace rf
