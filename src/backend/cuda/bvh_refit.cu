// The BVH refit on the device, after the box pass of Karras 2012 ("Maximizing
// Parallelism in the Construction of BVHs, Octrees, and k-d Trees", HPG 2012,
// sec. 4) applied to an existing tree, running the steps of
// accel/bvh/refit_steps.h that the CPU refit (accel/bvh/refit.cpp) runs:
//  1. parents: one thread per node (once per topology);
//  2. refit: one thread per leaf; it recomputes its leaf's box from the
//     triangles and climbs; an atomic counter per node stops the first child
//     to arrive, the second computes the parent's box (left child first) and
//     resets the counter, so the counters need no clearing between frames.
// Data layout: the canonical BvhNode array on the device, with per-node
// parents and counters and the leaves' node indices beside it.
// Determinism: boxes are unions with std::min/max semantics in a fixed
// order, bit-identical to the CPU refit whatever the thread schedule.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include "accel/bvh/refit_steps.h"
#include "backend/backends.h"
#include "backend/cuda/bvh_refit.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/launch.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

__global__ void parents_kernel(const BvhNode* nodes, uint32_t node_count, uint32_t* parents) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < node_count) refit::parent_step(nodes, i, parents);
}

__global__ void refit_kernel(DeviceRefitArrays arrays) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= arrays.leaf_count) return;
    const refit::RefitView view{arrays.nodes, arrays.parents, arrays.prim_indices, arrays.triangles, arrays.arrivals};
    refit::refit_from_leaf<karras::AtomicArrival>(view, arrays.leaves[i]);
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

void compute_refit_parents_on_device(const BvhNode* nodes, uint32_t node_count, uint32_t* parents) {
    launch(parents_kernel, node_count, nodes, node_count, parents);
}

void refit_bvh_on_device(const DeviceRefitArrays& arrays) { launch(refit_kernel, arrays.leaf_count, arrays); }

struct DeviceBvhRefit::Impl {
    DeviceBuffer<BvhNode> nodes{"refit: nodes"};
    DeviceBuffer<uint32_t> slots{"refit: primitive slots"}, leaves{"refit: leaves"};
    DeviceBuffer<uint32_t> parents{"refit: parents"}, arrivals{"refit: arrival counters"};
    DeviceBuffer<Triangle> triangles{"refit: triangles"};
    uint32_t leaf_count = 0;
    size_t triangle_count = 0;  // the largest slot + 1: fewer triangles would be read past
    int device = 0;
    EventTimer timer;
};

DeviceBvhRefit::DeviceBvhRefit(const Bvh& bvh, int device) {
    if (bvh.nodes.size() >= refit::kNoParent) throw Error("device refit: more than 2^32-2 nodes");
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    impl_ = std::make_unique<Impl>();  // its events on this device
    Impl& d = *impl_;
    d.device = device;
    std::vector<uint32_t> leaves;
    for (size_t i = 0; i < bvh.nodes.size(); ++i) {
        if (bvh.nodes[i].is_leaf()) leaves.push_back(uint32_t(i));
    }
    for (uint32_t prim : bvh.prim_indices) d.triangle_count = std::max<size_t>(d.triangle_count, size_t(prim) + 1);
    d.leaf_count = uint32_t(leaves.size());
    d.nodes.upload(bvh.nodes);
    d.slots.upload(bvh.prim_indices);
    d.leaves.upload(leaves);
    d.parents.allocate(bvh.nodes.size());
    d.arrivals.allocate(bvh.nodes.size());
    if (bvh.nodes.empty()) return;
    RF_CUDA_CHECK(cudaMemset(d.arrivals.data(), 0, d.arrivals.bytes()));
    compute_refit_parents_on_device(d.nodes.data(), uint32_t(bvh.nodes.size()), d.parents.data());
    RF_CUDA_CHECK(cudaDeviceSynchronize());
}

DeviceBvhRefit::~DeviceBvhRefit() = default;

double DeviceBvhRefit::refit(std::span<const Triangle> triangles) {
    Impl& d = *impl_;
    if (triangles.size() < d.triangle_count) {
        throw Error("device refit: " + std::to_string(triangles.size()) + " triangles, the tree names " +
                    std::to_string(d.triangle_count));
    }
    RF_CUDA_CHECK(cudaSetDevice(d.device));
    d.triangles.upload(triangles);
    d.timer.start();
    refit_bvh_on_device(arrays());
    return d.timer.stop_ms();
}

void DeviceBvhRefit::download(Bvh& bvh) const {
    if (bvh.nodes.size() != impl_->nodes.size()) throw Error("device refit: download into a tree of another size");
    RF_CUDA_CHECK(cudaSetDevice(impl_->device));
    impl_->nodes.download(bvh.nodes);
}

DeviceRefitArrays DeviceBvhRefit::arrays() const {
    const Impl& d = *impl_;
    return {d.nodes.data(),     d.parents.data(),  d.leaves.data(),          d.slots.data(),
            d.triangles.data(), d.arrivals.data(), uint32_t(d.nodes.size()), d.leaf_count};
}

size_t DeviceBvhRefit::bytes() const {
    const Impl& d = *impl_;
    return d.nodes.bytes() + d.slots.bytes() + d.leaves.bytes() + d.parents.bytes() + d.arrivals.bytes() +
           d.triangles.bytes();
}

DeviceRefitTimes refit_bvh_on_device(Bvh& bvh, std::span<const Triangle> triangles, int repeats, int device) {
    if (repeats < 1) throw Error("device refit: repeats must be at least 1, got " + std::to_string(repeats));
    DeviceRefitTimes times;
    if (bvh.nodes.empty()) return times;
    auto start = std::chrono::steady_clock::now();
    DeviceBvhRefit refit(bvh, device);  // includes the parents kernel
    times.upload_ms = elapsed_ms(start);
    double total = 0.0;
    for (int r = 0; r < repeats; ++r) {
        const double ms = refit.refit(triangles);
        times.refit_ms = r == 0 ? ms : std::min(times.refit_ms, ms);
        total += ms;
    }
    times.refit_mean_ms = total / repeats;
    start = std::chrono::steady_clock::now();
    refit.download(bvh);
    times.download_ms = elapsed_ms(start);
    return times;
}

}  // namespace rf::cuda
