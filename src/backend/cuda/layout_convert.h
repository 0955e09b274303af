// The layout conversions of layout_convert.cu for a canonical BVH already in
// device memory (device_bvh.h): the traced layout is written into the
// caller's buffers (DeviceTracer's own), and only counts cross to the host.
// The host-side entry points (convert_to_aila_laine_on_device and
// build_cwbvh_on_device, device_builders.h) upload a host Bvh and run the
// same passes. For .cu files only (CUDA headers).
#pragma once

#include <cstddef>
#include <cstdint>

#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "backend/cuda/device_bvh.h"

namespace rf::cuda {

// What a resident conversion leaves besides its arrays.
struct ResidentAilaLaine {
    int32_t root = kAilaLaineEntrySentinel;  // 0, ~0 for a root leaf (AilaLaineBvh::root)
    uint32_t node_count = 0;                 // node pairs
    size_t float4s = 0;                      // leaf-list entries
    size_t leaf_count = 0, triangle_refs = 0;
    [[nodiscard]] size_t memory_bytes() const {
        return size_t{node_count} * sizeof(AilaLaineNode) + float4s * sizeof(AilaLaineFloat4);
    }
};

struct ResidentCwbvh {
    uint32_t node_count = 0, triangle_count = 0;
    size_t leaf_count = 0;  // leaf slots
    int depth = 0;          // wide levels
    [[nodiscard]] size_t memory_bytes() const {
        return size_t{node_count} * sizeof(CwbvhNode) + size_t{triangle_count} * sizeof(CwbvhTriangle);
    }
};

// Node pairs of `in` into `nodes` and `leaf_lists` (reallocated to their
// exact sizes): the arrays convert_to_aila_laine gives for the same tree.
// The tree is trusted to be a builder's (every inner node two children,
// every reference in one leaf); its totals are derived from the node and
// reference counts and checked against the device's root sizes (one 16-byte
// copy), rf::Error when they differ. device_ms: the kernels (CUDA events).
ResidentAilaLaine convert_to_aila_laine_resident(const DeviceCanonicalView& in, DeviceBuffer<AilaLaineNode>& nodes,
                                                 DeviceBuffer<AilaLaineFloat4>& leaf_lists, double* device_ms,
                                                 int device);

// The CWBVH of `in` into `nodes` and `triangles` (exact sizes): build_cwbvh's
// arrays for the same tree. Counts crossing to the host: the refined node
// total (one copy before the passes), the wide levels' records (lagging
// asynchronous copies, then one read), the totals and counters at the end
// (consistency, node count).
ResidentCwbvh build_cwbvh_resident(const DeviceCanonicalView& in, DeviceBuffer<CwbvhNode>& nodes,
                                   DeviceBuffer<CwbvhTriangle>& triangles, double* device_ms, int device);

}  // namespace rf::cuda
