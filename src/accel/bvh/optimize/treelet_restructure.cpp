// Post-build BVH optimizer by treelet restructuring (Karras and Aila 2013,
// "Fast Parallel Construction of High-Quality Bounding Volume Hierarchies",
// HPG 2013, §4 and §5).
//
// Each round walks the tree bottom up, every canonical leaf climbing until it
// is the first of two children to reach a node, exactly the CUDA pass's
// schedule (backend/cuda/treelet_restructure.cu): the second child's walk
// processes the node, restructuring the treelet below it when the node
// roots at least gamma primitives (treelet_restructure_steps.h has the
// treelet formation, the dynamic programme and the relinking). gamma = n in
// the first round and doubles every round (§5). Disjoint subtrees are
// independent, so the leaves' walks run in parallel (TBB, core/parallel.h),
// and every node's result depends only on its subtree: the same tree for
// any thread count and on the device.
//
// The restructured topology then goes through the Morton builders' emitter
// (morton::RawTree over the input's leaf slots): the leaf collapse of the
// paper's §4.3 (formula 2, within the leaf-size limit), the depth limit,
// and the canonical depth-first layout. The result replaces the input only
// if its SAH cost is not higher (a guard against float rounding).
#include "accel/bvh/optimize/treelet_restructure.h"

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/morton_tree.h"
#include "accel/bvh/optimize/treelet_restructure_steps.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace treelet {
namespace {

constexpr uint32_t kNodeGrain = 4096;
constexpr uint32_t kLeafGrain = 256;
constexpr uint32_t kNone = 0xffffffffu;

// The working arrays of treelet_restructure_steps.h's TreeView.
struct WorkingTree {
    explicit WorkingTree(size_t nodes) {
        budgeted_resize(children, 2 * nodes, "treelet restructuring: child pairs");
        budgeted_resize(parents, nodes, "treelet restructuring: parents");
        budgeted_resize(boxes, nodes, "treelet restructuring: boxes");
        budgeted_resize(counts, nodes, "treelet restructuring: counts");
        budgeted_resize(costs, nodes, "treelet restructuring: costs");
        budgeted_resize(arrivals, nodes, "treelet restructuring: arrival counters");
    }
    TreeView view(const Bvh& bvh, const BvhBuildConfig& config, int treelet_leaves) {
        return {bvh.nodes.data(), children.data(), parents.data(), boxes.data(),   counts.data(),
                costs.data(),     arrivals.data(), emit_costs(config), 0u,          treelet_leaves};
    }
    std::vector<uint32_t> children, parents, counts, arrivals;
    std::vector<Box3f> boxes;
    std::vector<float> costs;
};

}  // namespace

uint32_t round_gamma(const TreeletOptions& options, int round) {
    return static_cast<uint32_t>(options.treelet_leaves) << round;
}

raw_emit::Costs emit_costs(const BvhBuildConfig& config) {
    return {config.sah.traversal, config.sah.intersection,
            static_cast<uint32_t>(std::clamp(config.max_leaf_size, 1, 255))};
}

void check_input(const Bvh& bvh, std::span<const Triangle> triangles, const TreeletOptions& options) {
    if (options.treelet_leaves < kMinLeaves || options.treelet_leaves > kMaxLeaves) {
        throw Error("treelet restructuring: treelet_leaves must be in [" + std::to_string(kMinLeaves) + ", " +
                    std::to_string(kMaxLeaves) + "], got " + std::to_string(options.treelet_leaves));
    }
    if (options.rounds < 1 || options.rounds > 16) {
        throw Error("treelet restructuring: rounds must be in [1, 16], got " + std::to_string(options.rounds));
    }
    if (bvh.nodes.size() >= raw_emit::kLeafRef || bvh.prim_indices.size() >= raw_emit::kLeafRef) {
        throw Error("treelet restructuring: more than 2^31-1 nodes or leaf slots");
    }
    for (const BvhNode& node : bvh.nodes) {
        if (!node.is_leaf()) continue;
        if (node.count > 255) {
            throw Error("treelet restructuring: a leaf of " + std::to_string(node.count) +
                        " primitives (at most 255)");
        }
        if (size_t{node.first} + node.count > bvh.prim_indices.size()) {
            throw Error("treelet restructuring: a leaf's slots run past the primitive indices");
        }
    }
    for (const uint32_t prim : bvh.prim_indices) {
        if (prim >= triangles.size()) {
            throw Error("treelet restructuring: primitive " + std::to_string(prim) + " of " +
                        std::to_string(triangles.size()) + " triangles");
        }
    }
}

Bvh emit_restructured(const Bvh& input, std::span<const Triangle> triangles, const BvhBuildConfig& config,
                      std::span<const uint32_t> raw_children) {
    const auto node_count = static_cast<uint32_t>(input.nodes.size());
    const auto slots = static_cast<uint32_t>(input.prim_indices.size());
    morton::RawTree raw(triangles, config);
    raw.order = input.prim_indices;
    raw.boxes.allocate(slots, "treelet restructuring: slot boxes");
    raw.enable_leaf_runs();
    raw.nodes.resize(node_count);
    std::vector<uint32_t> parents(node_count, kNone), arrivals(node_count, 0);
    parallel::for_range(0u, node_count, kNodeGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) {
            const BvhNode& node = input.nodes[i];
            if (node.is_leaf()) {
                leaf_slot_boxes(node, input.prim_indices.data(), triangles.data(), raw.boxes.data());
                raw.set_leaf_run(node.first, node.count);
                continue;
            }
            for (int side = 0; side < 2; ++side) {
                const uint32_t child = raw_children[2 * size_t{i} + side];
                if (!raw_emit::is_leaf_ref(child)) parents[child] = i;
            }
        }
    });
    // Bottom up as the rounds went: a walk starts at every node above a leaf
    // and the second child's walk finalizes a node (box, count, cost, collapse).
    const auto walk_up = [&](uint32_t node) {
        for (; node != kNone; node = parents[node]) {
            if (karras::AtomicArrival::arrive(&arrivals[node]) == 0) return;
            raw.finalize(node, raw_children[2 * size_t{node}], raw_children[2 * size_t{node} + 1]);
        }
    };
    parallel::for_range(0u, node_count, kNodeGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) {
            if (input.nodes[i].is_leaf()) continue;
            for (int side = 0; side < 2; ++side) {
                if (raw_emit::is_leaf_ref(raw_children[2 * size_t{i} + side])) walk_up(i);
            }
        }
    });
    return raw.emit(0);
}

void keep_if_not_worse(Bvh& bvh, Bvh&& optimized, const SahCosts& sah) {
    if (optimized.sah_cost(sah.traversal, sah.intersection) <= bvh.sah_cost(sah.traversal, sah.intersection)) {
        bvh = std::move(optimized);
    }
}

}  // namespace treelet

void optimize_treelets(Bvh& bvh, std::span<const Triangle> triangles, const BvhBuildConfig& config,
                       const TreeletOptions& options) {
    treelet::check_input(bvh, triangles, options);
    const auto node_count = static_cast<uint32_t>(bvh.nodes.size());
    if (node_count < 3) return;  // a leaf, or a root over two leaves: one topology
    treelet::WorkingTree work(node_count);
    treelet::TreeView view = work.view(bvh, config, options.treelet_leaves);
    std::vector<uint32_t> leaves;
    leaves.reserve((node_count + 1) / 2);
    for (uint32_t i = 0; i < node_count; ++i) {
        if (bvh.nodes[i].is_leaf()) leaves.push_back(i);
    }
    parallel::for_range(0u, node_count, treelet::kNodeGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) treelet::init_node(view, i);
    });
    for (int round = 0; round < options.rounds; ++round) {
        view.gamma = treelet::round_gamma(options, round);
        parallel::for_range(size_t{0}, leaves.size(), size_t{treelet::kLeafGrain}, [&](size_t lo, size_t hi) {
            for (size_t i = lo; i != hi; ++i) treelet::restructure_from_leaf<karras::AtomicArrival>(view, leaves[i]);
        });
    }
    std::vector<uint32_t> raw_children(2 * size_t{node_count});
    parallel::for_range(0u, node_count, treelet::kNodeGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) treelet::raw_children(view, i, raw_children.data());
    });
    treelet::keep_if_not_worse(bvh, treelet::emit_restructured(bvh, triangles, config, raw_children), config.sah);
}

}  // namespace rf
