// The BVH refit on a CUDA device (bvh_refit.cu): the steps of
// accel/bvh/refit_steps.h, one thread per node for the parents and one per
// leaf for the boxes. No CUDA header is needed to include this; without the
// CUDA backend every entry throws (backend/cuda_unavailable.cpp).
#pragma once

#include <cstdint>
#include <memory>
#include <span>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Milliseconds of one host-entry refit. Kernels are timed with CUDA events.
struct DeviceRefitTimes {
    double upload_ms = 0.0;       // the topology to the device and its parents kernel (once per tree)
    double refit_ms = 0.0;        // the refit kernel, best of the repeats (the triangles' upload excluded)
    double refit_mean_ms = 0.0;   // the refit kernel, mean of the repeats
    double download_ms = 0.0;     // the nodes back to the host
};

// Host entry: uploads `bvh` and `triangles` (moved; the ones its
// prim_indices index), refits on device `device` `repeats` times (>= 1; the
// same boxes every time) and downloads the nodes into `bvh`. The boxes are
// bit-identical to rf::refit_bvh's.
DeviceRefitTimes refit_bvh_on_device(Bvh& bvh, std::span<const Triangle> triangles, int repeats = 1,
                                     int device = 0);

// What the refit kernel reads and writes; all pointers are device memory.
struct DeviceRefitArrays {
    BvhNode* nodes = nullptr;                // node_count; boxes rewritten
    const uint32_t* parents = nullptr;       // node_count (compute_refit_parents_on_device)
    const uint32_t* leaves = nullptr;        // leaf_count node indices
    const uint32_t* prim_indices = nullptr;  // the Bvh's leaf slots
    const Triangle* triangles = nullptr;     // current positions
    uint32_t* arrivals = nullptr;            // node_count, zero before the first refit (a refit leaves them zero)
    uint32_t node_count = 0;
    uint32_t leaf_count = 0;
};

// Device entries, queued on the default stream. Once per topology: each
// node's parent. Per frame: every box of arrays.nodes from arrays.triangles.
void compute_refit_parents_on_device(const BvhNode* nodes, uint32_t node_count, uint32_t* parents);
void refit_bvh_on_device(const DeviceRefitArrays& arrays);

// A tree's topology kept on a device and refitted frame after frame: the
// nodes, slots, leaves, parents (computed there) and counters are uploaded
// once; each refit uploads the triangles and runs the kernel.
class DeviceBvhRefit {
public:
    explicit DeviceBvhRefit(const Bvh& bvh, int device = 0);
    ~DeviceBvhRefit();
    DeviceBvhRefit(const DeviceBvhRefit&) = delete;
    DeviceBvhRefit& operator=(const DeviceBvhRefit&) = delete;
    // Uploads `triangles` (the tree's, moved) and refits; returns the
    // kernel's milliseconds (CUDA events), the upload excluded.
    double refit(std::span<const Triangle> triangles);
    // The nodes with the last refit's boxes, to the host (topology unchanged).
    void download(Bvh& bvh) const;
    // The device arrays, for a device accel that traces the nodes in place
    // or refits from triangles it keeps itself (refit_bvh_on_device).
    [[nodiscard]] DeviceRefitArrays arrays() const;
    // Device memory held (nodes, slots, leaves, parents, counters, triangles).
    [[nodiscard]] size_t bytes() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace rf::cuda
