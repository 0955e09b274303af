// Canonical emission of a Morton-family raw tree on the device: the steps of
// accel/bvh/builders/raw_tree_emit_steps.h (parents, the bottom-up finalize
// with arrival counters, then one launch per level top down), then the
// nodes and primitive indices back to the host. Only the root's values
// cross to the host in between: its output size sizes the node buffer, its
// height says whether the depth limit sends the tree to the host's emitter,
// and otherwise how many level launches follow, back to back.
#include <cuda_runtime.h>

#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <string>

#include "accel/bvh/builders/raw_tree_emit_steps.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/cuda_check.h"
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

struct AtomicCounter {
    __device__ static uint32_t add(uint32_t* counter, uint32_t n) { return atomicAdd(counter, n); }
};

// One level of the top-down emission. The grid is fixed (launched before
// the level's size is known, with no host round trip between levels), so
// threads stride over the level's items.
__global__ void emit_level_kernel(raw_emit::RawTreeView tree, const raw_emit::EmitItem* items, const uint32_t* count,
                                  raw_emit::EmitItem* next, uint32_t* next_count, BvhNode* nodes,
                                  uint32_t* prim_indices) {
    const uint32_t items_in_level = *count;
    for (uint32_t i = blockIdx.x * kBlockSize + threadIdx.x; i < items_in_level; i += gridDim.x * kBlockSize) {
        raw_emit::emit_item<AtomicCounter>(tree, items[i], nodes, prim_indices, next, next_count);
    }
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

// The root's values, which decide the rest (n >= 2, so the root is a node).
raw_emit::NodeInfo root_values(const DeviceRawTree& tree, const raw_emit::RawTreeView& view,
                               const std::string& label) {
    if (raw_emit::is_leaf_ref(tree.root) || tree.root >= tree.node_slots) {
        throw Error(label + " device emission: the root is not a node");
    }
    const uint32_t root_value = view.dense != nullptr ? download_value(view.dense + tree.root) : tree.root;
    const raw_emit::NodeInfo root = download_value(view.info + root_value);
    if (root.count != tree.primitives) {
        throw Error(label + " device emission: the tree holds " + std::to_string(root.count) + " of " +
                    std::to_string(tree.primitives) + " primitives");
    }
    return root;
}

// The level launches' grid: as many blocks as the device keeps resident.
uint32_t resident_blocks() {
    int device = 0, processors = 1;
    RF_CUDA_CHECK(cudaGetDevice(&device));
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&processors, cudaDevAttrMultiProcessorCount, device));
    return static_cast<uint32_t>(processors) * 8u;
}

// Stage 3, timed: top down, one launch per level, back to back (a level
// holds at most as many items as the emitted tree has leaves,
// (out_size + 1) / 2); then the BVH back to the host.
void emit_levels(const raw_emit::RawTreeView& view, const raw_emit::NodeInfo& root, const std::string& label,
                 BuildContext& build, Bvh& out) {
    const uint32_t n = view.primitives, levels = raw_emit::emit_levels(root);
    const uint32_t widest = (root.out_size + 1) / 2;
    DeviceBuffer<BvhNode> nodes(build.meter, label + ": BVH nodes", root.out_size);
    DeviceBuffer<uint32_t> prims(build.meter, label + ": BVH primitive indices", n),
        counts(build.meter, label + ": emission level sizes", size_t{levels} + 1);
    DeviceBuffer<raw_emit::EmitItem> items[2] = {
        DeviceBuffer<raw_emit::EmitItem>(build.meter, label + ": emission level A", widest),
        DeviceBuffer<raw_emit::EmitItem>(build.meter, label + ": emission level B", widest)};
    const uint32_t grid = strided_blocks_for(widest, resident_blocks());
    const raw_emit::EmitItem first = raw_emit::root_item(view.root);
    const uint32_t one = 1;
    build.timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(counts.data(), 0, counts.bytes()));
    RF_CUDA_CHECK(cudaMemcpyAsync(counts.data(), &one, sizeof one, cudaMemcpyHostToDevice));
    RF_CUDA_CHECK(cudaMemcpyAsync(items[0].data(), &first, sizeof first, cudaMemcpyHostToDevice));
    for (uint32_t level = 0; level < levels; ++level) {
        launch_shaped(emit_level_kernel, {grid}, view, items[level & 1].data(), counts.data() + level,
                      items[(level + 1) & 1].data(), counts.data() + level + 1, nodes.data(), prims.data());
    }
    build.stages.device_emit_ms += build.timer.stop_ms();
    // Items queued below the last level: none in a tree of that height.
    if (download_value(counts.data() + levels) != 0) {
        throw Error(label + " device emission: the tree is deeper than its root's height");
    }
    build.stages.peak_device_bytes = std::max(build.stages.peak_device_bytes, build.meter.peak());

    build.timer.start();
    out.nodes.resize(root.out_size);
    out.prim_indices.resize(n);
    nodes.download(out.nodes);
    prims.download(out.prim_indices);
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

    const raw_emit::NodeInfo root = root_values(tree, view, label);
    if (!raw_emit::fits_depth_limit(root)) return false;
    emit_levels(view, root, label, build, out);
    return true;
}

}  // namespace rf::cuda
