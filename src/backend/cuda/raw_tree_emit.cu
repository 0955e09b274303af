// Canonical emission of a Morton-family raw tree on the device: the steps of
// accel/bvh/builders/raw_tree_emit_steps.h (parents, the bottom-up finalize
// with acquire-release arrival counters, then ONE launch in which every node
// slot sums its depth-first position over its ancestors), then the nodes
// and primitive indices back to the host. Only the root's values cross to
// the host in between, in one copy: its output size sizes the node buffer,
// its height says whether the depth limit sends the tree to the host's
// emitter. (For sparse numberings the used-slot count also comes back, to
// size the node values.)
#include <cuda_runtime.h>

#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <string>

#include "accel/bvh/builders/raw_tree_emit_steps.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/cuda_check.h"
#include "backend/cuda/device_bvh.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

__global__ void scatter_parents_kernel(raw_emit::RawTreeView tree) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < tree.node_slots) raw_emit::scatter_parents(tree, i);
}

__global__ void used_slots_kernel(raw_emit::RawTreeView tree, uint32_t* used) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < tree.node_slots) used[i] = raw_emit::used_slot(tree, i);
}

__global__ void finalize_kernel(raw_emit::RawTreeView tree) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < tree.primitives) raw_emit::finalize_from_leaf<karras::AtomicArrival>(tree, i);
}

// Stage 3 in one launch: one thread per node slot finds its depth-first
// position from the subtree sizes of its ancestors and writes its output
// node and its leaf children's (raw_emit::emit_node).
__global__ void emit_nodes_kernel(raw_emit::RawTreeView tree, BvhNode* nodes, uint32_t* prim_indices) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < tree.node_slots) raw_emit::emit_node(tree, i, nodes, prim_indices);
}

// The root's values where the host reads them in one copy (through the
// dense numbering when there is one).
__global__ void root_values_kernel(raw_emit::RawTreeView tree, raw_emit::NodeInfo* out) {
    *out = raw_emit::node_info(tree, tree.root);
}

// The steps' view of `tree`; the emission's own arrays are set by its stages.
raw_emit::RawTreeView raw_tree_view(const DeviceRawTree& tree, const BvhBuildConfig& config) {
    raw_emit::RawTreeView view{};
    view.children = tree.children;
    view.high_children = tree.high_children;
    view.high_base = tree.high_children != nullptr ? tree.high_base : tree.node_slots;
    view.node_slots = tree.node_slots;
    view.root = tree.root;
    view.primitives = tree.primitives;
    view.boxes = tree.boxes;
    view.boxes_by_triangle = tree.boxes_by_triangle;
    view.order = tree.order;
    view.leaf_runs = tree.leaf_runs;
    view.costs = {config.sah.traversal, config.sah.intersection,
                  static_cast<uint32_t>(std::clamp(config.max_leaf_size, 1, 255))};
    // Read only by the emitter; the view's pointers are shared with the
    // builder's arrays (null: the emitter scatters its own).
    view.node_parent = const_cast<uint32_t*>(tree.node_parent);
    view.leaf_parent = const_cast<uint32_t*>(tree.leaf_parent);
    return view;
}

// Sparse slots: the used ones' value indices (empty otherwise).
struct SlotNumbering {
    DeviceBuffer<uint32_t> dense;
    uint32_t values = 0;  // nodes that get values
};

// Stage 1, timed: the parents the builder did not give (into the view's
// arrays) and, for sparse slots, the dense numbering of the used ones by a
// prefix sum; the marks and the scan's scratch are freed on return.
SlotNumbering scatter_parents_and_number_slots(const DeviceRawTree& tree, const raw_emit::RawTreeView& view,
                                               bool own_parents, const std::string& label, BuildContext& build) {
    const uint32_t slots = tree.node_slots;
    const size_t marks = tree.sparse_slots ? size_t{slots} + 1 : 0;
    SlotNumbering numbering{DeviceBuffer<uint32_t>(build.meter, label + ": emission value indices", marks), slots};
    DeviceBuffer<uint32_t> used(build.meter, label + ": emission used slots", marks);
    DeviceBuffer<uint8_t> scratch(build.meter, label + ": emission scan temporary storage");
    const auto scan = [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::ExclusiveSum(temp, bytes, used.data(), numbering.dense.data(), slots + 1);
    };
    if (tree.sparse_slots) cub_reserve(scratch, scan);  // allocated outside the timed kernels
    build.timer.start();
    if (own_parents) {
        RF_CUDA_CHECK(cudaMemsetAsync(view.node_parent, 0xff, size_t{slots} * sizeof(uint32_t)));
        RF_CUDA_CHECK(cudaMemsetAsync(view.leaf_parent, 0xff, size_t{tree.primitives} * sizeof(uint32_t)));
        launch(scatter_parents_kernel, slots, view);
    }
    if (tree.sparse_slots) {
        RF_CUDA_CHECK(cudaMemsetAsync(used.data() + slots, 0, sizeof(uint32_t)));
        launch(used_slots_kernel, slots, view, used.data());
        cub_run(scratch, scan);
    }
    build.stages.device_emit_ms += build.timer.stop_ms();
    if (tree.sparse_slots) numbering.values = download_value(numbering.dense.data() + slots);
    return numbering;
}

// Stage 2, timed: every node's values bottom up, into view.info; the
// arrival counters are freed on return.
void finalize_nodes(raw_emit::RawTreeView view, uint32_t values, const std::string& label, BuildContext& build) {
    DeviceBuffer<uint32_t> arrivals(build.meter, label + ": emission arrival counters", values);
    view.arrivals = arrivals.data();
    build.timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    launch(finalize_kernel, view.primitives, view);
    build.stages.device_emit_ms += build.timer.stop_ms();
}

// The root's values, which decide the rest (n >= 2, so the root is a
// node): one small kernel gathers them, one copy brings them over.
raw_emit::NodeInfo root_values(const DeviceRawTree& tree, const raw_emit::RawTreeView& view,
                               const std::string& label, BuildContext& build) {
    if (raw_emit::is_leaf_ref(tree.root) || tree.root >= tree.node_slots) {
        throw Error(label + " device emission: the root is not a node");
    }
    DeviceBuffer<raw_emit::NodeInfo> gathered(build.meter, label + ": emission root values", 1);
    launch_shaped(root_values_kernel, {1, 1}, view, gathered.data());
    const raw_emit::NodeInfo root = download_value(gathered.data());
    if (root.count != tree.primitives) {
        throw Error(label + " device emission: the tree holds " + std::to_string(root.count) + " of " +
                    std::to_string(tree.primitives) + " primitives");
    }
    return root;
}

// Stage 3, timed: the canonical layout in one launch (emit_nodes_kernel);
// then the BVH back to the host, unless build.resident keeps it on the
// device. The result's buffers are unmetered (a resident one outlives the
// build): they count as live alongside the emission's peak.
void emit_nodes(const raw_emit::RawTreeView& view, const raw_emit::NodeInfo& root, const std::string& label,
                BuildContext& build, Bvh& out) {
    const uint32_t n = view.primitives;
    DeviceBvh local;
    DeviceBvh& result = build.resident ? *build.resident : local;
    result.nodes = DeviceBuffer<BvhNode>(label + ": BVH nodes", root.out_size);
    result.prim_indices = DeviceBuffer<uint32_t>(label + ": BVH primitive indices", n);
    build.timer.start();
    launch(emit_nodes_kernel, view.node_slots, view, result.nodes.data(), result.prim_indices.data());
    build.stages.device_emit_ms += build.timer.stop_ms();
    build.stages.peak_device_bytes = std::max(build.stages.peak_device_bytes, build.meter.peak() +
                                              result.nodes.bytes() + result.prim_indices.bytes());
    if (build.resident) return;

    build.timer.start();
    out.nodes.resize(root.out_size);
    out.prim_indices.resize(n);
    result.nodes.download(out.nodes);
    result.prim_indices.download(out.prim_indices);
    build.stages.download_ms += build.timer.stop_ms();
}

}  // namespace

bool emit_raw_tree_on_device(const DeviceRawTree& tree, const BvhBuildConfig& config, const std::string& label,
                             BuildContext& build, Bvh& out) {
    raw_emit::RawTreeView view = raw_tree_view(tree, config);
    const bool own_parents = tree.node_parent == nullptr;
    DeviceBuffer<uint32_t> node_parent(build.meter, label + ": emission node parents",
                                       own_parents ? tree.node_slots : 0);
    SlotNumbering numbering;
    DeviceBuffer<raw_emit::NodeInfo> info;
    {
        // Leaf parents: read by the bottom-up pass only.
        DeviceBuffer<uint32_t> leaf_parent(build.meter, label + ": emission leaf parents",
                                           own_parents ? tree.primitives : 0);
        if (own_parents) {
            view.node_parent = node_parent.data();
            view.leaf_parent = leaf_parent.data();
        }
        numbering = scatter_parents_and_number_slots(tree, view, own_parents, label, build);
        view.dense = numbering.dense.data();
        info = DeviceBuffer<raw_emit::NodeInfo>(build.meter, label + ": emission node values", numbering.values);
        view.info = info.data();
        finalize_nodes(view, numbering.values, label, build);
    }
    if (own_parents) view.leaf_parent = nullptr;  // the top-down pass walks only node parents

    const raw_emit::NodeInfo root = root_values(tree, view, label, build);
    if (!raw_emit::fits_depth_limit(root)) return false;
    emit_nodes(view, root, label, build, out);
    return true;
}

}  // namespace rf::cuda
