// HLBVH2 builder (Garanzha 2014, dissertation ch. 5, "BVH construction with
// binary search and work queues"; Garanzha, Pantaleoni and McAllister,
// HPG 2011). Parameters as in Garanzha 2014, ch. 5:
//
//  1. 30-bit Morton codes (n = 10 bits per axis) of the triangles' box
//     centres in the centroid bounds.
//  2. One radix sort of (code, triangle) pairs.
//  3. Clusters by compaction: runs of equal top 15 bits (m = 5), i.e. the
//     non-empty cells of a 32^3 grid; at most 32,768.
//  4. Bottom levels, one per cluster: a node over sorted range [a, b) splits
//     where the highest bit in which codes[a] and codes[b-1] differ turns
//     from 0 to 1, found by binary search (O(log n) code reads; geometrically
//     a midpoint split of the node's Morton cell). A range of at most
//     numLeafTri (= config.max_leaf_size) triangles is a leaf. Ranges whose
//     codes are all equal are halved by position (hlbvh2_bottom_steps.h,
//     shared with the CUDA builder, which finds each node from its split
//     position). The GPU work queues (one node per thread, one level per
//     launch) become TBB tasks: clusters in
//     parallel, and large ranges split into parallel subtasks. Boxes are
//     computed bottom-up as the recursion returns.
//  5. Top level over the clusters, each an indivisible primitive with its
//     box, by the grid SAH of ch. 4 with the top grid only: candidate planes
//     lie on the 32^3 cluster grid, at most 8 bins (7 planes) per axis across
//     the node's integer cell bounds; cost = area(L) * triangles(L) +
//     area(R) * triangles(R); a stable partition of the clusters. The steps
//     are hlbvh2_top_steps.h's, shared with the CUDA builder's task queues.
//  6. The shared emitter (morton_tree.cpp) bounds the depth to kBvhMaxDepth
//     and writes the canonical depth-first layout.
// Node indices are fixed by the input (bottom inner node = its split position
// - 1; top nodes numbered by their cluster ranges), so the tree is the same
// for every thread count. emit_hlbvh2_forest() takes bottom trees (and,
// optionally, the top level) built elsewhere (the CUDA builder) and finishes
// them with the same top level and emitter.
#include "accel/bvh/builders/hlbvh2.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <utility>

#include "accel/bvh/builders/hlbvh2_emit.h"
#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "accel/bvh/builders/hlbvh2_top_steps.h"
#include "accel/bvh/builders/morton_radix_sort.h"
#include "accel/bvh/builders/morton_tree.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using morton::kLeafRef;

constexpr int kCodeBits = 30;
constexpr int kClusterShift = 15;                  // clusters: the top 15 of 30 bits
constexpr uint32_t kParallelRange = 4096;          // triangles per range to split into tasks
constexpr uint32_t kParallelTop = 256;             // clusters per top node to split into tasks
constexpr uint32_t kCompactBlock = 64 * 1024;
static_assert(hlbvh2::kLeafRef == kLeafRef && hlbvh2::kCodeBits == kCodeBits &&
              hlbvh2::kClusterShift == kClusterShift, "the shared task steps use this builder's encoding");

class Stopwatch {
public:
    double lap() {
        const auto now = std::chrono::steady_clock::now();
        const double ms = std::chrono::duration<double, std::milli>(now - last_).count();
        last_ = now;
        return ms;
    }
private:
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

// The CPU's top level: the task at `task` over clusters[first, end), its
// children recursively (in parallel when large); see hlbvh2_top_steps.h.
void build_top_task(std::span<hlbvh2::TopCluster> clusters, const hlbvh2::TopTask& task, uint32_t top_base,
                    uint32_t* top_refs) {
    const hlbvh2::CellBounds bounds = hlbvh2::strided_cell_bounds(clusters.data(), task.first, task.end, 0, 1);
    hlbvh2::TopBin bins[3][hlbvh2::kTopBins];
    hlbvh2::bin_task(clusters.data(), task.first, task.end, bounds, bins);
    uint32_t left_count = (task.end - task.first) / 2;  // no plane (clusters sharing a cell): halve
    const hlbvh2::TopSplit split = hlbvh2::choose_split(bins, bounds, &left_count);
    if (split.axis >= 0) {
        std::stable_partition(clusters.begin() + task.first, clusters.begin() + task.end,
                              [&](const hlbvh2::TopCluster& c) { return hlbvh2::goes_left(c, bounds, split); });
    }
    hlbvh2::TopTask children[2];
    hlbvh2::child_tasks(task, left_count, children);
    for (int side = 0; side < 2; ++side) {
        top_refs[2 * task.node + side] = hlbvh2::child_reference(children[side], clusters.data(), top_base);
    }
    auto build_child = [&](int side) {
        if (children[side].end - children[side].first >= 2) build_top_task(clusters, children[side], top_base, top_refs);
    };
    if (task.end - task.first > kParallelTop) {
        parallel::invoke([&] { build_child(0); }, [&] { build_child(1); });
    } else {
        build_child(0);
        build_child(1);
    }
}

class Hlbvh2Builder {
public:
    Hlbvh2Builder(std::span<const Triangle> triangles, const BvhBuildConfig& config)
        : tree_(triangles, config), leaf_size_(static_cast<uint32_t>(std::max(config.max_leaf_size, 1))) {}

    Bvh build(Hlbvh2Stages& stages) {
        Stopwatch clock;
        double code_ms = 0.0;
        static_assert(kCodeBits == 30, "uint32_t keys give 30-bit codes");
        tree_.sort_by_morton_codes(keys_, &code_ms);
        const double sorted_ms = clock.lap();
        stages.morton_ms = code_ms;
        stages.sort_ms = std::max(0.0, sorted_ms - code_ms);
        const uint32_t n = tree_.size();
        if (n == 0) return {};

        find_clusters();
        const uint32_t clusters = static_cast<uint32_t>(cluster_begin_.size() - 1);
        stages.cluster_count = clusters;
        stages.clusters_ms = clock.lap();

        tree_.enable_leaf_runs();
        budgeted_resize(tree_.nodes, size_t{n} - 1 + (clusters - 1), "HLBVH2: nodes");
        budgeted_resize(cluster_root_, clusters, "HLBVH2: cluster roots");
        parallel::for_range(0u, clusters, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t c = lo; c != hi; ++c) cluster_root_[c] = build_range(cluster_begin_[c], cluster_begin_[c + 1]);
        });
        stages.bottom_ms = clock.lap();

        const uint32_t root = build_top(clusters);
        stages.top_ms = clock.lap();

        Bvh bvh = tree_.emit(root);
        stages.emit_ms = clock.lap();
        return bvh;
    }

    // The same tree from bottom levels built elsewhere (emit_hlbvh2_forest).
    Bvh build_from_forest(Hlbvh2Forest&& forest, Hlbvh2Stages& stages) {
        if (forest.order.size() != tree_.triangles.size()) throw Error("HLBVH2 emission: order and triangles differ in size");
        if (forest.order.size() >= kLeafRef) throw Error("Morton BVH build: more than 2^31-1 triangles");
        const uint32_t n = static_cast<uint32_t>(forest.order.size());
        if (n == 0) return {};
        const size_t clusters = forest.cluster_prefix.size();
        if (clusters == 0 || forest.cluster_begin.size() != clusters + 1 || forest.cluster_begin[0] != 0 ||
            forest.cluster_begin[clusters] != n || forest.refs.size() != 2 * (size_t{n} - 1) + clusters) {
            throw Error("HLBVH2 emission: inconsistent cluster or reference arrays");
        }
        for (size_t c = 0; c < clusters; ++c) {
            if (forest.cluster_begin[c] >= forest.cluster_begin[c + 1]) throw Error("HLBVH2 emission: empty cluster");
        }
        Stopwatch clock;
        tree_.set_order(std::move(forest.order));
        tree_.enable_leaf_runs();
        budgeted_resize(tree_.nodes, size_t{n} - 1 + (clusters - 1), "HLBVH2: nodes");
        cluster_begin_ = std::move(forest.cluster_begin);
        cluster_prefix_ = std::move(forest.cluster_prefix);
        refs_ = std::move(forest.refs);
        top_refs_ = std::move(forest.top_refs);
        budgeted_resize(cluster_root_, clusters, "HLBVH2: cluster roots");
        std::atomic<bool> malformed{false};
        parallel::for_range(uint32_t{0}, static_cast<uint32_t>(clusters), 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t c = lo; c != hi; ++c) {
                const uint32_t root = refs_[2 * (size_t{n} - 1) + c];
                cluster_root_[c] = root;
                if (!refit_range(root, cluster_begin_[c], cluster_begin_[c + 1], 0)) malformed = true;
            }
        });
        if (malformed) throw Error("HLBVH2 emission: malformed bottom tree");
        stages.bottom_ms = clock.lap();
        const uint32_t root = build_top(static_cast<uint32_t>(clusters));
        stages.top_ms = clock.lap();
        Bvh bvh = tree_.emit(root);
        stages.emit_ms = clock.lap();
        return bvh;
    }

private:
    // Starts of the runs of equal 15-bit prefixes, plus n at the end.
    void find_clusters() {
        const uint32_t n = tree_.size();
        const uint32_t blocks = (n + kCompactBlock - 1) / kCompactBlock;
        auto is_start = [&](uint32_t i) { return i == 0 || (keys_[i] >> kClusterShift) != (keys_[i - 1] >> kClusterShift); };
        std::vector<uint32_t> block_offset(blocks + 1, 0);
        parallel::for_range(0u, blocks, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t b = lo; b != hi; ++b) {
                uint32_t starts = 0;
                for (uint32_t i = b * kCompactBlock, end = std::min(n, i + kCompactBlock); i != end; ++i) starts += is_start(i);
                block_offset[b + 1] = starts;
            }
        });
        for (uint32_t b = 0; b < blocks; ++b) block_offset[b + 1] += block_offset[b];
        cluster_begin_.assign(block_offset[blocks] + 1, n);
        parallel::for_range(0u, blocks, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t b = lo; b != hi; ++b) {
                uint32_t at = block_offset[b];
                for (uint32_t i = b * kCompactBlock, end = std::min(n, i + kCompactBlock); i != end; ++i) {
                    if (is_start(i)) cluster_begin_[at++] = i;
                }
            }
        });
    }

    // Finalizes the downloaded subtree `ref` over sorted range [a, b),
    // checking that it is what process_task makes; false when it is not.
    bool refit_range(uint32_t ref, uint32_t a, uint32_t b, int depth) {
        const uint32_t count = b - a;
        if (morton::is_leaf_ref(ref)) {
            if ((ref & ~kLeafRef) != a || count > leaf_size_) return false;
            tree_.set_leaf_run(a, count);
            return true;
        }
        const uint32_t mid = ref + 1;
        // Ranges shrink by one at least per level, and 64 levels of 30-bit codes
        // then halvings cover 2^31 primitives: deeper means a cycle.
        if (count <= leaf_size_ || mid <= a || mid >= b || depth > 96) return false;
        const uint32_t left = refs_[2 * size_t{ref}], right = refs_[2 * size_t{ref} + 1];
        if (!refit_range(left, a, mid, depth + 1) || !refit_range(right, mid, b, depth + 1)) return false;
        tree_.finalize(ref, left, right);
        return true;
    }

    // The bottom-level subtree over sorted range [a, b); returns its reference.
    uint32_t build_range(uint32_t a, uint32_t b) {
        const uint32_t count = b - a;
        if (count <= leaf_size_) {
            tree_.set_leaf_run(a, count);
            return kLeafRef | a;
        }
        const uint32_t mid = hlbvh2::split_position(keys_.data(), a, b);
        uint32_t left, right;
        if (count > kParallelRange) {
            parallel::invoke([&] { left = build_range(a, mid); }, [&] { right = build_range(mid, b); });
        } else {
            left = build_range(a, mid);
            right = build_range(mid, b);
        }
        const uint32_t index = mid - 1;  // each split position occurs once
        tree_.finalize(index, left, right);
        return index;
    }

    // The top level over the clusters (the CPU's, or the forest's given
    // one), then every top node finalized: children are numbered above
    // their parent, so descending numbers see final children.
    uint32_t build_top(uint32_t count) {
        top_base_ = tree_.size() - 1;
        if (count == 1) {
            if (!top_refs_.empty()) throw Error("HLBVH2 emission: top level of the wrong size");
            return cluster_root_[0];
        }
        if (top_refs_.empty()) {
            std::vector<hlbvh2::TopCluster> clusters(count);
            parallel::for_range(0u, count, 64u, [&](uint32_t lo, uint32_t hi) {
                for (uint32_t c = lo; c != hi; ++c) {
                    const uint32_t prefix =
                        cluster_prefix_.empty() ? keys_[cluster_begin_[c]] >> kClusterShift : cluster_prefix_[c];
                    clusters[c] = {tree_.bounds(cluster_root_[c]), hlbvh2::pack_cells(prefix),
                                   cluster_begin_[c + 1] - cluster_begin_[c], cluster_root_[c]};
                }
            });
            top_refs_ = build_hlbvh2_top_level(clusters, top_base_);
        } else {
            check_top_level(count);
        }
        for (uint32_t k = count - 1; k-- > 0;) tree_.finalize(top_base_ + k, top_refs_[2 * k], top_refs_[2 * k + 1]);
        return top_base_;
    }

    // A given top level must be a tree over exactly the cluster roots: each
    // top node but the root, and each cluster root, referenced once, and
    // top children numbered above their parent (so no cycle).
    void check_top_level(uint32_t count) const {
        const uint32_t n = tree_.size();
        if (top_refs_.size() != 2 * (size_t{count} - 1)) throw Error("HLBVH2 emission: top level of the wrong size");
        enum : uint8_t { kFree = 0, kRoot = 1, kUsed = 2 };
        std::vector<uint8_t> bottom(2 * size_t{n}, kFree), top(count - 1, kFree);
        auto bottom_slot = [&](uint32_t ref) -> size_t { return morton::is_leaf_ref(ref) ? n + (ref & ~kLeafRef) : ref; };
        for (uint32_t c = 0; c < count; ++c) bottom[bottom_slot(cluster_root_[c])] = kRoot;
        for (uint32_t k = 0; k + 1 < count; ++k) {
            for (int side = 0; side < 2; ++side) {
                const uint32_t ref = top_refs_[2 * size_t{k} + side];
                if (!morton::is_leaf_ref(ref) && ref >= top_base_) {
                    const uint32_t child = ref - top_base_;
                    if (child >= count - 1 || child <= k || top[child] != kFree) {
                        throw Error("HLBVH2 emission: malformed top level");
                    }
                    top[child] = kUsed;
                } else {
                    const size_t slot = bottom_slot(ref);
                    if (slot >= bottom.size() || bottom[slot] != kRoot) throw Error("HLBVH2 emission: malformed top level");
                    bottom[slot] = kUsed;
                }
            }
        }
        // 2 (count - 1) references, each to a distinct node of count - 2 top
        // nodes and count clusters: all of them.
    }

    morton::RawTree tree_;
    uint32_t leaf_size_;
    morton::Buffer<uint32_t> keys_;
    std::vector<uint32_t> cluster_begin_;
    std::vector<uint32_t> cluster_root_;
    std::vector<uint32_t> cluster_prefix_;  // given with a forest; else read from keys_
    std::vector<uint32_t> refs_;            // a forest's references
    std::vector<uint32_t> top_refs_;        // the top level: 2 per top node (given with a forest, or built)
    uint32_t top_base_ = 0;                 // top node k is node top_base_ + k
};

}  // namespace

Bvh build_hlbvh2(std::span<const Triangle> triangles, const BvhBuildConfig& config, Hlbvh2Stages* stages) {
    Hlbvh2Stages local;
    Hlbvh2Builder builder(triangles, config);
    Bvh bvh = builder.build(local);
    if (stages) *stages = local;
    return bvh;
}

Bvh emit_hlbvh2_forest(std::span<const Triangle> triangles, const BvhBuildConfig& config, Hlbvh2Forest&& forest,
                       Hlbvh2Stages* stages) {
    Hlbvh2Stages local;
    Hlbvh2Builder builder(triangles, config);
    Bvh bvh = builder.build_from_forest(std::move(forest), local);
    if (stages) {
        stages->top_ms = local.top_ms;
        stages->emit_ms = local.bottom_ms + local.emit_ms;  // the bottom refit is part of the host's emission
    }
    return bvh;
}

Bvh build_hlbvh2(std::span<const Triangle> triangles, const BvhBuildConfig& config) {
    return build_hlbvh2(triangles, config, nullptr);
}

std::vector<uint32_t> build_hlbvh2_top_level(std::span<hlbvh2::TopCluster> clusters, uint32_t top_base) {
    const uint32_t count = static_cast<uint32_t>(clusters.size());
    if (count < 2) return {};
    std::vector<uint32_t> top_refs(2 * (size_t{count} - 1));
    build_top_task(clusters, hlbvh2::TopTask{0, count, 0}, top_base, top_refs.data());
    return top_refs;
}

}  // namespace rf
