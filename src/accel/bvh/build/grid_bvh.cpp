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
//    (options' C_trav, C_int) says a split is cheaper (the dissertation stops
//    at <= 4 references; on the bunny, Sponza and Conference that cost 2-4%
//    SAH at C_trav = C_int = 1).
// 5. Canonical emission: subtree sizes and boxes bottom-up per tree level
//    (levelOffset of Algorithm 4.1), then positions top-down, giving the
//    depth-first layout of rf::Bvh.
//
// The per-task step of 3 (process_task), the cell keys and the sparse-grid
// reads are grid_bvh_steps.h's, shared with the CUDA builder
// (backend/cuda/grid_bvh_build.cu), which hands its hierarchy to steps 4-5
// here through emit_grid_bvh_hierarchy (grid_bvh_emit.h).
//
// Depth: a grid split at depth d is taken only if d + 1 + the halving levels
// of its larger side stay within kBvhMaxDepth; otherwise the task becomes a
// large leaf whose finishing falls back to median splits in time. Every
// decision depends on the input alone (fixed block sizes, ordered queues), so
// the tree is the same for every thread count.
#include "accel/bvh/build/grid_bvh.h"
#include "accel/bvh/build/grid_bvh_emit.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/build/grid_bvh_partial_triangles.h"
#include "accel/bvh/build/grid_bvh_sparse_grid.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using gridbvh::CellBox;
using gridbvh::GridFrame;
using gridbvh::GridRef;
using gridbvh::kLeafBit;
using gridbvh::median_levels;
using gridbvh::NodeRegion;
using gridbvh::SparseGrid;
using gridbvh::SplitTask;
using gridbvh::TaskOutcome;
constexpr int kFinishBins = 8;
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

// A finished leaf of the grid hierarchy. Usually one BvhNode whose triangle
// indices sit in leaf_prims_ at its reference range; a large leaf gets a small
// tree in canonical relative layout (node 0 its root; inner `first` is a local
// node index, leaf `first` a local slot) and its own triangle indices.
struct LocalTree {
    Box3f box;
    uint32_t prim_count = 0;
    uint32_t node_count = 1;
    std::vector<BvhNode> nodes;   // empty for a single leaf
    std::vector<uint32_t> prims;  // empty for a single leaf
};

class GridBvhBuilder {
public:
    GridBvhBuilder(std::span<const Triangle> triangles, const BuildOptions& options, bool partial_triangles,
                   GridBvhStages& stages)
        : triangles_(triangles),
          max_leaf_size_(uint32_t(std::max(1, options.max_leaf_size))),
          traversal_cost_(options.traversal_cost),
          intersection_cost_(options.intersection_cost),
          split_budget_(options.split_budget),
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

        start = std::chrono::steady_clock::now();
        finish_leaves();
        stages_.leaf_finish_ms = ms_since(start);

        start = std::chrono::steady_clock::now();
        emit_canonical(bvh);
        stages_.emission_ms = ms_since(start);
        stages_.total_ms = ms_since(total_start);
        frame_ = nullptr;
        return bvh;
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
        budgeted_resize(leaf_prims_, n, "GridBvh: leaf triangles");
        std::atomic<size_t> large{0};
        parallel::for_range(0u, leaf_count, 64u, [&](uint32_t lo, uint32_t hi) {
            std::vector<GridRef> refs;
            for (uint32_t l = lo; l < hi; ++l) {
                // Reference order within a leaf is fixed by sorting, whatever
                // the order the scatter above ran in.
                uint32_t* begin = leaf_refs_.data() + leaf_begin_[l];
                uint32_t* end = leaf_refs_.data() + leaf_begin_[l + 1];
                std::sort(begin, end);
                refs.clear();
                for (const uint32_t* r = begin; r != end; ++r) refs.push_back(refs_[*r]);
                merge_parts(refs);
                LocalTree& tree = trees_[l];
                tree.prim_count = uint32_t(refs.size());
                if (refs.size() <= max_leaf_size_ && keep_as_leaf(refs.data(), uint32_t(refs.size()))) {
                    Box3f box;
                    for (size_t k = 0; k < refs.size(); ++k) {
                        box = {vmin(box.lo, refs[k].lo), vmax(box.hi, refs[k].hi)};
                        leaf_prims_[leaf_begin_[l] + k] = refs[k].prim;
                    }
                    tree.box = box;
                    tree.node_count = 1;
                    continue;
                }
                if (refs.size() > max_leaf_size_) large.fetch_add(1, std::memory_order_relaxed);
                tree.nodes.reserve(2 * refs.size() - 1);
                tree.prims.reserve(refs.size());
                tree.nodes.resize(1);
                build_local(tree, refs.data(), uint32_t(refs.size()), leaves_[l].depth, 0);
                tree.box = tree.nodes[0].bounds;
                tree.node_count = uint32_t(tree.nodes.size());
            }
        });
        stages_.large_leaves = large.load();
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

    // Parts of one triangle in one leaf become one reference (union box).
    static void merge_parts(std::vector<GridRef>& refs) {
        // Stable insertion sort by triangle: leaves are small.
        for (size_t i = 1; i < refs.size(); ++i) {
            const GridRef r = refs[i];
            size_t j = i;
            for (; j > 0 && refs[j - 1].prim > r.prim; --j) refs[j] = refs[j - 1];
            refs[j] = r;
        }
        size_t out = 0;
        for (size_t i = 0; i < refs.size(); ++i) {
            if (out > 0 && refs[out - 1].prim == refs[i].prim) {
                refs[out - 1].lo = vmin(refs[out - 1].lo, refs[i].lo);
                refs[out - 1].hi = vmax(refs[out - 1].hi, refs[i].hi);
            } else {
                refs[out++] = refs[i];
            }
        }
        refs.resize(out);
    }

    // Whether `count` (<= max_leaf_size) references stay one leaf: unless a
    // binned split is cheaper by the SAH (C_trav, C_int of the options), as
    // in the binned builder. May reorder the references.
    bool keep_as_leaf(GridRef* refs, uint32_t count) const {
        if (count <= 1) return true;
        Box3f bounds, centroids;
        for (uint32_t i = 0; i < count; ++i) {
            bounds = {vmin(bounds.lo, refs[i].lo), vmax(bounds.hi, refs[i].hi)};
            const Vec3f c = refs[i].centroid();
            centroids = {vmin(centroids.lo, c), vmax(centroids.hi, c)};
        }
        float cost = 0.0f;
        const uint32_t mid = split_binned(refs, count, centroids, cost);
        const float area = bounds.surface_area();
        return mid == 0 || mid == count ||
               traversal_cost_ * area + intersection_cost_ * cost >= intersection_cost_ * area * float(count);
    }

    // Builds tree.nodes[node] over refs[0, count) at tree depth `depth`:
    // binned SAH over centroids with SAH termination, leaves of at most
    // max_leaf_size, median splits when the depth limit comes near or all
    // centroids coincide. Large ranges build their halves as parallel tasks
    // into separate trees, joined in canonical order.
    void build_local(LocalTree& tree, GridRef* refs, uint32_t count, int depth, uint32_t node) const {
        Box3f bounds, centroids;
        for (uint32_t i = 0; i < count; ++i) {
            bounds = {vmin(bounds.lo, refs[i].lo), vmax(bounds.hi, refs[i].hi)};
            const Vec3f c = refs[i].centroid();
            centroids = {vmin(centroids.lo, c), vmax(centroids.hi, c)};
        }
        tree.nodes[node].bounds = bounds;
        float cost = 0.0f;
        uint32_t mid = count > 1 ? split_binned(refs, count, centroids, cost) : 0;
        const bool no_split = mid == 0 || mid == count;
        const float area = bounds.surface_area();
        if (count <= max_leaf_size_ &&
            (no_split || traversal_cost_ * area + intersection_cost_ * cost >= intersection_cost_ * area * float(count))) {
            tree.nodes[node].first = uint32_t(tree.prims.size());
            tree.nodes[node].count = count;
            for (uint32_t i = 0; i < count; ++i) tree.prims.push_back(refs[i].prim);
            return;
        }
        const uint32_t larger = std::max(mid, count - mid);
        if (no_split || depth + 1 + median_levels(larger, max_leaf_size_) > kBvhMaxDepth) {
            mid = split_median(refs, count, centroids);
        }
        if (count > kParallelFinishSize) {
            LocalTree left, right;
            left.nodes.resize(1);
            right.nodes.resize(1);
            parallel::invoke([&] { build_local(left, refs, mid, depth + 1, 0); },
                             [&] { build_local(right, refs + mid, count - mid, depth + 1, 0); });
            append_children(tree, node, left, right);
            return;
        }
        const uint32_t pair = uint32_t(tree.nodes.size());
        tree.nodes.resize(pair + 2);
        tree.nodes[node].first = pair;
        tree.nodes[node].count = 0;
        build_local(tree, refs, mid, depth + 1, pair);
        build_local(tree, refs + mid, count - mid, depth + 1, pair + 1);
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

    // Binned SAH over the references' centroids; returns the left count
    // after partitioning (0 when no split separates them).
    static uint32_t split_binned(GridRef* refs, uint32_t count, const Box3f& centroids, float& cost) {
        struct Bin {
            Box3f box;
            uint32_t count = 0;
        };
        const Vec3f extent = centroids.extent();
        int best_axis = -1, best_bin = 0;
        float best_cost = 0.0f;
        for (int a = 0; a < 3; ++a) {
            if (!(extent[a] > 0.0f)) continue;
            const float scale = float(kFinishBins) * (1.0f - 0x1p-20f) / extent[a];
            Bin bins[kFinishBins];
            for (uint32_t i = 0; i < count; ++i) {
                const int b = std::clamp(int((refs[i].centroid()[a] - centroids.lo[a]) * scale), 0, kFinishBins - 1);
                bins[b].box = {vmin(bins[b].box.lo, refs[i].lo), vmax(bins[b].box.hi, refs[i].hi)};
                ++bins[b].count;
            }
            float right_area[kFinishBins];
            uint32_t right_count[kFinishBins];
            Box3f acc;
            uint32_t n = 0;
            for (int i = kFinishBins - 1; i > 0; --i) {
                acc = {vmin(acc.lo, bins[i].box.lo), vmax(acc.hi, bins[i].box.hi)};
                n += bins[i].count;
                right_area[i] = acc.surface_area();
                right_count[i] = n;
            }
            acc = Box3f{};
            n = 0;
            for (int i = 1; i < kFinishBins; ++i) {
                acc = {vmin(acc.lo, bins[i - 1].box.lo), vmax(acc.hi, bins[i - 1].box.hi)};
                n += bins[i - 1].count;
                if (n == 0 || right_count[i] == 0) continue;
                const float cost = acc.surface_area() * float(n) + right_area[i] * float(right_count[i]);
                if (best_axis < 0 || cost < best_cost) {
                    best_axis = a;
                    best_bin = i;
                    best_cost = cost;
                }
            }
        }
        if (best_axis < 0) return 0;
        cost = best_cost;
        const float scale = float(kFinishBins) * (1.0f - 0x1p-20f) / extent[best_axis];
        auto goes_left = [&](const GridRef& r) {
            return std::clamp(int((r.centroid()[best_axis] - centroids.lo[best_axis]) * scale), 0, kFinishBins - 1) <
                   best_bin;
        };
        return uint32_t(std::stable_partition(refs, refs + count, goes_left) - refs);
    }

    // Object median on the widest centroid axis (ties by triangle index;
    // merged parts make indices unique); halves by position when all
    // centroids coincide.
    static uint32_t split_median(GridRef* refs, uint32_t count, const Box3f& centroids) {
        const uint32_t mid = count / 2;
        const Vec3f extent = centroids.extent();
        if (extent.x > 0.0f || extent.y > 0.0f || extent.z > 0.0f) {
            const int axis = centroids.largest_axis();
            std::nth_element(refs, refs + mid, refs + count, [axis](const GridRef& a, const GridRef& b) {
                const float ca = a.lo[axis] + a.hi[axis], cb = b.lo[axis] + b.hi[axis];
                return ca < cb || (ca == cb && a.prim < b.prim);
            });
        }
        return mid;
    }

    // Boxes and sizes bottom-up per tree level, positions top-down, then the copy.
    void emit_canonical(Bvh& bvh) const {
        const size_t count = hnodes_.size();
        std::vector<uint32_t> sub_nodes(count), sub_prims(count), pos(count), desc(count), prim_base(count);
        std::vector<Box3f> box(count);
        const size_t levels = level_offset_.size() - 1;
        for (size_t l = levels; l-- > 0;) {
            parallel::for_range(size_t{level_offset_[l]}, size_t{level_offset_[l + 1]}, size_t{1024},
                                [&](size_t lo, size_t hi) {
                                    for (size_t h = lo; h < hi; ++h) {
                                        const uint32_t first = hnodes_[h];
                                        if (first & kLeafBit) {
                                            const LocalTree& t = trees_[first & ~kLeafBit];
                                            sub_nodes[h] = t.node_count;
                                            sub_prims[h] = t.prim_count;
                                            box[h] = t.box;
                                        } else {
                                            sub_nodes[h] = 1 + sub_nodes[first] + sub_nodes[first + 1];
                                            sub_prims[h] = sub_prims[first] + sub_prims[first + 1];
                                            box[h] = merge(box[first], box[first + 1]);
                                        }
                                    }
                                });
        }
        pos[0] = 0;
        desc[0] = 1;
        prim_base[0] = 0;
        for (size_t l = 0; l < levels; ++l) {
            parallel::for_range(size_t{level_offset_[l]}, size_t{level_offset_[l + 1]}, size_t{1024},
                                [&](size_t lo, size_t hi) {
                                    for (size_t h = lo; h < hi; ++h) {
                                        const uint32_t first = hnodes_[h];
                                        if (first & kLeafBit) continue;
                                        const uint32_t left = first, right = first + 1;
                                        pos[left] = desc[h];
                                        pos[right] = desc[h] + 1;
                                        desc[left] = desc[h] + 2;
                                        desc[right] = desc[left] + sub_nodes[left] - 1;
                                        prim_base[left] = prim_base[h];
                                        prim_base[right] = prim_base[h] + sub_prims[left];
                                    }
                                });
        }
        budgeted_resize(bvh.nodes, sub_nodes[0], "BVH nodes");
        budgeted_resize(bvh.prim_indices, sub_prims[0], "BVH primitive indices");
        parallel::for_range(size_t{0}, count, size_t{1024}, [&](size_t lo, size_t hi) {
            for (size_t h = lo; h < hi; ++h) {
                const uint32_t first = hnodes_[h];
                if (!(first & kLeafBit)) {
                    BvhNode& out = bvh.nodes[pos[h]];
                    out.bounds = box[h];
                    out.first = desc[h];
                    out.count = 0;
                    continue;
                }
                const uint32_t leaf = first & ~kLeafBit;
                const LocalTree& t = trees_[leaf];
                if (t.nodes.empty()) {
                    BvhNode& out = bvh.nodes[pos[h]];
                    out.bounds = t.box;
                    out.first = prim_base[h];
                    out.count = t.prim_count;
                    std::copy_n(leaf_prims_.begin() + leaf_begin_[leaf], t.prim_count,
                                bvh.prim_indices.begin() + prim_base[h]);
                    continue;
                }
                for (size_t j = 0; j < t.nodes.size(); ++j) {
                    BvhNode node = t.nodes[j];
                    node.first = node.is_leaf() ? prim_base[h] + node.first : desc[h] + node.first - 1;
                    bvh.nodes[j == 0 ? pos[h] : desc[h] + j - 1] = node;
                }
                std::copy(t.prims.begin(), t.prims.end(), bvh.prim_indices.begin() + prim_base[h]);
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
    std::vector<uint32_t> leaf_prims_;    // triangle indices of single-node leaves, at their range
    std::vector<LocalTree> trees_;        // per leaf task: its finished subtree
};

}  // namespace

Bvh build_grid_bvh(std::span<const Triangle> triangles, const BuildOptions& options, bool partial_triangles,
                   GridBvhStages* stages) {
    GridBvhStages local;
    GridBvhBuilder builder(triangles, options, partial_triangles, stages ? *stages : local);
    return parallel::with_threads(options.threads, [&] { return builder.build(); });
}

Bvh emit_grid_bvh_hierarchy(std::span<const Triangle> triangles, const BuildOptions& options, bool partial_triangles,
                            GridHierarchy&& hierarchy, GridBvhStages* stages) {
    GridBvhStages local;
    GridBvhBuilder builder(triangles, options, partial_triangles, stages ? *stages : local);
    return parallel::with_threads(options.threads, [&] { return builder.emit(std::move(hierarchy)); });
}

Bvh build_grid_bvh(std::span<const Triangle> triangles, const BuildOptions& options, bool partial_triangles) {
    return build_grid_bvh(triangles, options, partial_triangles, nullptr);
}

}  // namespace rf
