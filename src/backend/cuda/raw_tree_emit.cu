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
#include "backend/cuda/cuda_check.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

constexpr int kBlockSize = 256;

uint32_t blocks_for(uint64_t threads) { return static_cast<uint32_t>((threads + kBlockSize - 1) / kBlockSize); }

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

}  // namespace

bool emit_raw_tree_on_device(const DeviceRawTree& tree, const BvhBuildConfig& config, const std::string& label,
                             MemoryMeter& meter, EventTimer& timer, DeviceBuildStages& stages, Bvh& out) {
    const uint32_t n = tree.primitives, slots = tree.node_slots;
    DeviceBuffer<uint32_t> node_parent(label + ": emission node parents"), leaf_parent(label + ": emission leaf parents"),
        arrivals(label + ": emission arrival counters");
    DeviceBuffer<raw_emit::NodeInfo> info(label + ": emission node values");
    raw_emit::RawTreeView view{};
    view.children = tree.children;
    view.high_children = tree.high_children;
    view.high_base = tree.high_children != nullptr ? tree.high_base : slots;
    view.node_slots = slots;
    view.root = tree.root;
    view.primitives = n;
    view.boxes = tree.boxes;
    view.boxes_by_triangle = tree.boxes_by_triangle;
    view.order = tree.order;
    view.leaf_runs = tree.leaf_runs;
    view.costs = {config.sah.traversal, config.sah.intersection,
                  static_cast<uint32_t>(std::clamp(config.max_leaf_size, 1, 255))};
    const bool own_parents = tree.node_parent == nullptr;
    if (own_parents) {
        meter.allocate(node_parent, slots);
        meter.allocate(leaf_parent, n);
        view.node_parent = node_parent.data();
        view.leaf_parent = leaf_parent.data();
    } else {
        // Read only by the emitter; the view's pointers are shared with the builder's arrays.
        view.node_parent = const_cast<uint32_t*>(tree.node_parent);
        view.leaf_parent = const_cast<uint32_t*>(tree.leaf_parent);
    }

    // Sparse numberings: node values only for the slots in use (allocated
    // here, outside the timed kernels).
    DeviceBuffer<uint32_t> dense(label + ": emission value indices"), used(label + ": emission used slots");
    DeviceBuffer<uint8_t> scan_temp(label + ": emission scan temporary storage");
    size_t temp_bytes = 0;
    if (tree.sparse_slots) {
        meter.allocate(used, size_t{slots} + 1);
        meter.allocate(dense, size_t{slots} + 1);
        RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, used.data(), dense.data(), slots + 1));
        meter.allocate(scan_temp, temp_bytes > 0 ? temp_bytes : 1);
    }

    timer.start();
    if (own_parents) {
        RF_CUDA_CHECK(cudaMemsetAsync(node_parent.data(), 0xff, node_parent.bytes()));
        RF_CUDA_CHECK(cudaMemsetAsync(leaf_parent.data(), 0xff, leaf_parent.bytes()));
        scatter_parents_kernel<<<blocks_for(slots), kBlockSize>>>(view);
    }
    uint32_t values = slots;
    if (tree.sparse_slots) {
        RF_CUDA_CHECK(cudaMemsetAsync(used.data() + slots, 0, sizeof(uint32_t)));
        used_slots_kernel<<<blocks_for(slots), kBlockSize>>>(view, used.data());
        RF_CUDA_CHECK(
            cub::DeviceScan::ExclusiveSum(scan_temp.data(), temp_bytes, used.data(), dense.data(), slots + 1));
    }
    stages.device_emit_ms += timer.stop_ms();
    if (tree.sparse_slots) {
        RF_CUDA_CHECK(cudaMemcpy(&values, dense.data() + slots, sizeof values, cudaMemcpyDeviceToHost));
        meter.release(scan_temp);
        meter.release(used);
        view.dense = dense.data();
    }
    meter.allocate(info, values);
    meter.allocate(arrivals, values);
    view.info = info.data();
    view.arrivals = arrivals.data();

    timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    finalize_kernel<<<blocks_for(n), kBlockSize>>>(view);
    stages.device_emit_ms += timer.stop_ms();
    meter.release(arrivals);
    if (own_parents) {  // the top-down pass walks only node parents
        meter.release(leaf_parent);
        view.leaf_parent = nullptr;
    }

    // The root's values decide the rest (n >= 2, so the root is a node).
    if (raw_emit::is_leaf_ref(tree.root) || tree.root >= slots) {
        throw Error(label + " device emission: the root is not a node");
    }
    raw_emit::NodeInfo root{};
    uint32_t root_value = tree.root;
    if (view.dense != nullptr) {
        RF_CUDA_CHECK(cudaMemcpy(&root_value, dense.data() + tree.root, sizeof root_value, cudaMemcpyDeviceToHost));
    }
    RF_CUDA_CHECK(cudaMemcpy(&root, info.data() + root_value, sizeof root, cudaMemcpyDeviceToHost));
    if (root.count != n) {
        throw Error(label + " device emission: the tree holds " + std::to_string(root.count) + " of " +
                    std::to_string(n) + " primitives");
    }
    if (!raw_emit::fits_depth_limit(root)) return false;

    // Top down, one launch per level; a level holds at most as many items as
    // the emitted tree has leaves, (out_size + 1) / 2.
    const uint32_t levels = raw_emit::emit_levels(root);
    DeviceBuffer<BvhNode> nodes(label + ": BVH nodes");
    DeviceBuffer<uint32_t> prims(label + ": BVH primitive indices"), counts(label + ": emission level sizes");
    DeviceBuffer<raw_emit::EmitItem> items[2] = {DeviceBuffer<raw_emit::EmitItem>(label + ": emission level A"),
                                                 DeviceBuffer<raw_emit::EmitItem>(label + ": emission level B")};
    meter.allocate(nodes, root.out_size);
    meter.allocate(prims, n);
    meter.allocate(counts, size_t{levels} + 1);
    const uint32_t widest = (root.out_size + 1) / 2;
    meter.allocate(items[0], widest);
    meter.allocate(items[1], widest);
    int device = 0, processors = 1;
    RF_CUDA_CHECK(cudaGetDevice(&device));
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&processors, cudaDevAttrMultiProcessorCount, device));
    const uint32_t grid = std::min(blocks_for(widest), static_cast<uint32_t>(processors) * 8u);
    const raw_emit::EmitItem first = raw_emit::root_item(tree.root);
    const uint32_t one = 1;
    timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(counts.data(), 0, counts.bytes()));
    RF_CUDA_CHECK(cudaMemcpyAsync(counts.data(), &one, sizeof one, cudaMemcpyHostToDevice));
    RF_CUDA_CHECK(cudaMemcpyAsync(items[0].data(), &first, sizeof first, cudaMemcpyHostToDevice));
    for (uint32_t level = 0; level < levels; ++level) {
        emit_level_kernel<<<grid, kBlockSize>>>(view, items[level & 1].data(), counts.data() + level,
                                                items[(level + 1) & 1].data(), counts.data() + level + 1, nodes.data(),
                                                prims.data());
    }
    stages.device_emit_ms += timer.stop_ms();
    uint32_t left_over = 0;  // items queued below the last level: none in a tree of that height
    RF_CUDA_CHECK(cudaMemcpy(&left_over, counts.data() + levels, sizeof left_over, cudaMemcpyDeviceToHost));
    if (left_over != 0) throw Error(label + " device emission: the tree is deeper than its root's height");
    for (auto* buffer : {&items[0], &items[1]}) meter.release(*buffer);
    meter.release(counts);
    meter.release(info);
    meter.release(dense);
    meter.release(node_parent);
    stages.peak_device_bytes = std::max(stages.peak_device_bytes, meter.peak());

    timer.start();
    out.nodes.resize(root.out_size);
    out.prim_indices.resize(n);
    nodes.download(out.nodes);
    prims.download(out.prim_indices);
    stages.download_ms += timer.stop_ms();
    return true;
}

}  // namespace rf::cuda
