// Treelet restructuring (Karras and Aila 2013, "Fast Parallel Construction
// of High-Quality Bounding Volume Hierarchies", HPG 2013, §4-5) on the
// device, running the steps of accel/bvh/optimize/treelet_restructure_steps.h
// that the CPU pass (accel/bvh/optimize/treelet_restructure.cpp) runs:
//  1. init: one thread per node builds the working tree (child pairs,
//     parents, boxes, counts, zeroed arrival counters);
//  2. one launch per round: one thread per canonical leaf walks up with
//     arrival counters (Karras 2012 sec. 4); the second child's thread
//     processes a node, and restructures the treelet below it, alone, when
//     the node roots at least gamma primitives. One thread per treelet,
//     where the paper has a warp cooperate on a treelet's dynamic programme:
//     simpler and the same result, slower at the top of the tree where few
//     treelets are left (unmeasured);
//  3. the final topology as a raw tree (raw child pairs, per-slot boxes and
//     leaf runs), emitted by the Morton builders' device emitter
//     (raw_tree_emit.cu: collapse, canonical layout), or on the host when
//     it is deeper than kBvhMaxDepth.
// Determinism: a node's result depends only on its subtree, and each
// product and sum is rounded once, so the tree is the CPU pass's bit for bit.
// The input comes from the host (every device builder downloads its tree
// today), so this pass uploads it and downloads the result.
#include <cuda_runtime.h>

#include <chrono>
#include <vector>

#include "accel/bvh/optimize/treelet_restructure.h"
#include "accel/bvh/optimize/treelet_restructure_steps.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/raw_tree_emit.h"
#include "backend/cuda/treelet_restructure.h"

namespace rf::cuda {
namespace {

__global__ void init_kernel(treelet::TreeView tree, uint32_t node_count) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < node_count) treelet::init_node(tree, i);
}

__global__ void round_kernel(treelet::TreeView tree, const uint32_t* leaves, uint32_t leaf_count) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < leaf_count) treelet::restructure_from_leaf<karras::AtomicArrival>(tree, leaves[i]);
}

__global__ void raw_tree_kernel(treelet::TreeView tree, uint32_t node_count, const uint32_t* prim_indices,
                                const Triangle* triangles, uint32_t* raw_children, Box3f* slot_boxes,
                                uint8_t* leaf_runs) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= node_count) return;
    treelet::raw_children(tree, i, raw_children);
    const BvhNode& node = tree.nodes[i];
    if (!node.is_leaf()) return;
    treelet::leaf_slot_boxes(node, prim_indices, triangles, slot_boxes);
    leaf_runs[node.first] = static_cast<uint8_t>(node.count);
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

void optimize_treelets_on_device(Bvh& bvh, std::span<const Triangle> triangles, const BvhBuildConfig& config,
                                 const TreeletOptions& options, DeviceBuildStages* stages, int device) {
    treelet::check_input(bvh, triangles, options);
    const auto node_count = static_cast<uint32_t>(bvh.nodes.size());
    if (node_count < 3) return;  // one topology only (the CPU pass returns here too)
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    DeviceBuildStages pass;  // the emitter's stage times, folded into s below
    BuildContext build(pass);
    const std::string label = "treelet restructuring";

    std::vector<uint32_t> leaves;
    leaves.reserve((node_count + 1) / 2);
    for (uint32_t i = 0; i < node_count; ++i) {
        if (bvh.nodes[i].is_leaf()) leaves.push_back(i);
    }
    const auto slots = static_cast<uint32_t>(bvh.prim_indices.size());
    auto start = std::chrono::steady_clock::now();
    DeviceBuffer<BvhNode> nodes(build.meter, label + ": input nodes");
    DeviceBuffer<uint32_t> prims(build.meter, label + ": primitive indices"),
        leaf_nodes(build.meter, label + ": leaf nodes");
    DeviceBuffer<Triangle> tris(build.meter, label + ": triangles");
    nodes.upload(bvh.nodes);
    prims.upload(bvh.prim_indices);
    leaf_nodes.upload(leaves);
    tris.upload(triangles);
    s.upload_ms += elapsed_ms(start);

    DeviceBuffer<uint32_t> children(build.meter, label + ": child pairs", 2 * size_t{node_count}),
        parents(build.meter, label + ": parents", node_count), counts(build.meter, label + ": counts", node_count),
        arrivals(build.meter, label + ": arrival counters", node_count);
    DeviceBuffer<Box3f> boxes(build.meter, label + ": boxes", node_count);
    DeviceBuffer<float> costs(build.meter, label + ": costs", node_count);
    treelet::TreeView view{nodes.data(),  children.data(), parents.data(),  boxes.data(),
                           counts.data(), costs.data(),    arrivals.data(), treelet::emit_costs(config),
                           0u,            options.treelet_leaves};
    DeviceBuffer<uint32_t> raw_children(build.meter, label + ": raw child pairs", 2 * size_t{node_count});
    DeviceBuffer<Box3f> slot_boxes(build.meter, label + ": slot boxes", slots);
    DeviceBuffer<uint8_t> leaf_runs(build.meter, label + ": leaf runs", slots);

    build.timer.start();
    launch(init_kernel, node_count, view, node_count);
    for (int round = 0; round < options.rounds; ++round) {
        view.gamma = treelet::round_gamma(options, round);
        launch(round_kernel, leaves.size(), view, leaf_nodes.data(), static_cast<uint32_t>(leaves.size()));
    }
    RF_CUDA_CHECK(cudaMemsetAsync(leaf_runs.data(), 0, leaf_runs.bytes()));
    launch(raw_tree_kernel, node_count, view, node_count, prims.data(), tris.data(), raw_children.data(),
           slot_boxes.data(), leaf_runs.data());
    s.treelet_ms += build.timer.stop_ms();

    DeviceRawTree tree;
    tree.children = raw_children.data();
    tree.node_slots = node_count;
    tree.root = 0;
    tree.primitives = slots;
    tree.boxes = slot_boxes.data();
    tree.boxes_by_triangle = false;
    tree.order = prims.data();
    tree.leaf_runs = leaf_runs.data();
    Bvh optimized;
    if (!emit_raw_tree_on_device(tree, config, label, build, optimized)) {
        // Deeper than kBvhMaxDepth: the host emitter's depth-limited rebuild.
        start = std::chrono::steady_clock::now();
        const std::vector<uint32_t> host_children = download_all(raw_children, raw_children.size());
        pass.download_ms += elapsed_ms(start);
        optimized = treelet::emit_restructured(bvh, triangles, config, host_children);
    }
    s.treelet_ms += pass.device_emit_ms;
    s.download_ms += pass.download_ms;
    s.peak_device_bytes = std::max(s.peak_device_bytes, build.meter.peak());
    treelet::keep_if_not_worse(bvh, std::move(optimized), config.sah);
}

}  // namespace rf::cuda
