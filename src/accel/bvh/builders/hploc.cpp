// H-PLOC builder (Benthin, Meister, Barczak, Mohan and Vaidyanathan 2024,
// "H-PLOC: Hierarchical Parallel Locally-Ordered Clustering for Bounding
// Volume Hierarchy Construction", HPG 2024), on the CPU.
//
//  1. 63-bit Morton codes of the triangles' box centres, radix-sorted
//     (morton_tree.cpp; the device sorts the same way).
//  2. The paper's single pass (its one-kernel build; the steps are
//     hploc_steps.h's, shared with backend/cuda/hploc_build.cu): the leaves
//     in warps of 32 lanes, one thread per leaf climbing the implicit LBVH
//     (Apetrei 2014); where a range spans more than 16 leaves, or at the
//     root, the warp clusters the range's children's clusters with PLOC
//     (Meister and Bittner 2018) down to at most 16 (one at the root). Here
//     a warp is a SimulatedWarp (its lanes a loop), and the warps run in
//     parallel tasks; the boundary slots are exchanged atomically
//     (acquire-release, which also publishes the clusters and nodes a warp
//     wrote before). The tree does not depend on which warp comes second,
//     so it is the same for every thread count and equals the device's.
//  3. Leaves: every node is finalized as it is made (box, count, SAH cost,
//     leaf collapse, RawTree::finalize), and the shared emitter
//     (morton_tree.cpp) bounds the depth to kBvhMaxDepth and writes the
//     canonical layout, as for LBVH and PLOC.
#include "accel/bvh/builders/hploc.h"

#include <algorithm>
#include <atomic>
#include <string>
#include <utility>

#include "accel/bvh/builders/hploc_steps.h"
#include "accel/bvh/builders/morton_tree.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using morton::kLeafRef;
static_assert(hploc::kLeafRef == morton::kLeafRef, "H-PLOC clusters are raw-tree references");

constexpr uint32_t kWarpGrain = 64;  // warps per parallel task
constexpr uint32_t kGrain = 16 * 1024;

// The warps' memory on the host: cluster slots, the raw tree's nodes
// (finalized as they are made), boundary slots exchanged atomically.
struct HostMemory {
    morton::RawTree& tree;
    uint32_t* clusters;

    uint32_t load_ref(uint32_t position) const { return clusters[position]; }
    void store_ref(uint32_t position, uint32_t ref) const { clusters[position] = ref; }
    Box3f box(uint32_t ref) const { return tree.bounds(ref); }
    void write_node(uint32_t node, uint32_t left, uint32_t right, const Box3f&) const {
        tree.finalize_unit_leaves(node, left, right);
    }
    uint32_t exchange(uint32_t* slot, uint32_t value) const {
        return __atomic_exchange_n(slot, value, __ATOMIC_ACQ_REL);
    }
    void publish() const {}  // the next exchange releases
};

class HplocBuilder {
public:
    HplocBuilder(std::span<const Triangle> triangles, const BvhBuildConfig& config, const PlocOptions& ploc_options)
        : tree_(triangles, config), radius_(hploc::clamp_radius(ploc_options.radius)) {}

    Bvh build() {
        morton::Buffer<uint64_t> keys;
        tree_.sort_by_morton_codes(keys);
        const uint32_t n = tree_.size();
        if (n == 0) return {};
        if (n == 1) return tree_.emit(kLeafRef | 0u);
        budgeted_resize(tree_.nodes, n - 1, "H-PLOC: nodes");
        morton::Buffer<uint32_t> clusters(n, "H-PLOC: clusters");
        morton::Buffer<uint32_t> boundary_slots(n - 1, "H-PLOC: boundary slots");
        parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) {
                clusters[i] = kLeafRef | i;
                if (i + 1 < n) boundary_slots[i] = hploc::kNoRangeEnd;
            }
        });
        uint32_t node_counter = 0;
        const hploc::Build build{keys.data(), n, boundary_slots.data(), &node_counter, radius_};
        const HostMemory memory{tree_, clusters.data()};
        std::atomic<bool> failed{false};
        const uint32_t warps = (n + hploc::kWarpLanes - 1) / hploc::kWarpLanes;
        parallel::for_range(0u, warps, kWarpGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t w = lo; w != hi; ++w) {
                if (!run_warp(build, memory, w)) failed = true;
            }
        });
        if (failed || node_counter != n - 1 || clusters[0] != n - 2) {
            throw Error("H-PLOC: the clustering made " + std::to_string(node_counter) + " nodes of " +
                        std::to_string(n - 1) + (failed ? ", a range could not be merged" : ""));
        }
        return tree_.emit(n - 2);
    }

private:
    // Warp w's leaves, round after round until none climbs; false when a
    // range could not be merged.
    static bool run_warp(const hploc::Build& build, HostMemory memory, uint32_t w) {
        hploc::SimulatedWarp warp;
        hploc::LaneArray<hploc::Range> range;
        for (uint32_t lane = 0; lane < hploc::kWarpLanes; ++lane) {
            range[lane] = hploc::leaf_range(w * hploc::kWarpLanes + lane, build.n);
        }
        bool failed = false;
        while (hploc::warp_round(warp, memory, build, range, &failed)) {
        }
        return !failed;
    }

    morton::RawTree tree_;
    uint32_t radius_;
};

// Every leaf and every node but the root n - 2 referenced exactly once, and
// each node only by a node numbered after it.
void check_hploc_tree(uint32_t n, std::span<const uint32_t> children) {
    if (children.size() != 2 * (size_t{n} - 1)) throw Error("H-PLOC emission: expected 2 (n - 1) child references");
    std::vector<uint8_t> used(2 * size_t{n} - 1, 0);  // leaves, then nodes
    for (uint32_t node = 0; node + 1 < n; ++node) {
        for (int c = 0; c < 2; ++c) {
            const uint32_t ref = children[2 * size_t{node} + c];
            const uint32_t index = ref & ~kLeafRef;
            const bool leaf = morton::is_leaf_ref(ref);
            if (leaf ? index >= n : index >= node) {
                throw Error("H-PLOC emission: node " + std::to_string(node) + " has an invalid child " +
                            std::to_string(ref));
            }
            if (used[leaf ? index : n + index]++ != 0) {
                throw Error("H-PLOC emission: child " + std::to_string(ref) + " referenced twice");
            }
        }
    }
}

}  // namespace

Bvh build_hploc(std::span<const Triangle> triangles, const BvhBuildConfig& config, const PlocOptions& ploc_options) {
    HplocBuilder builder(triangles, config, ploc_options);
    return builder.build();
}

Bvh emit_hploc_tree(std::span<const Triangle> triangles, const BvhBuildConfig& config, std::vector<uint32_t>&& order,
                    std::span<const uint32_t> children) {
    if (order.size() != triangles.size()) throw Error("H-PLOC emission: order and triangles differ in size");
    const uint32_t n = static_cast<uint32_t>(order.size());
    if (n == 0) return {};
    morton::RawTree tree(triangles, config);
    if (n == 1) {
        tree.set_order(std::move(order));
        return tree.emit(kLeafRef | 0u);
    }
    check_hploc_tree(n, children);
    tree.set_order(std::move(order));
    budgeted_resize(tree.nodes, n - 1, "H-PLOC: nodes");
    for (uint32_t i = 0; i + 1 < n; ++i) tree.finalize_unit_leaves(i, children[2 * size_t{i}], children[2 * size_t{i} + 1]);
    return tree.emit(n - 2);
}

}  // namespace rf
