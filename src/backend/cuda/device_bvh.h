// A canonical BVH left in device memory by a device build (issue 33 item 3):
// the device builders emit it there (raw_tree_emit.cu with
// BuildContext::resident set), the layout converters (layout_convert.h)
// read it there and write the traced layout into the tracer's own buffers,
// so nothing between the triangles' upload and the first ray crosses to
// the host but a few counts. The host Bvh (stats, refits) is downloaded
// after that. For .cu files only (CUDA headers).
#pragma once

#include <span>

#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/event_timer.h"
#include "rayforge/accel/bvh/bvh.h"

namespace rf::cuda {

// Unmetered buffers (they outlive the build whose meter counted the rest),
// sized exactly: nodes.size() nodes, prim_indices.size() references.
struct DeviceBvh {
    DeviceBuffer<BvhNode> nodes{"device BVH nodes"};
    DeviceBuffer<uint32_t> prim_indices{"device BVH primitive indices"};
    [[nodiscard]] bool empty() const { return nodes.size() == 0; }
};

// What a converter reads: the canonical BVH and its triangles in device memory.
struct DeviceCanonicalView {
    const BvhNode* nodes = nullptr;
    uint32_t node_count = 0;
    const uint32_t* prim_indices = nullptr;
    size_t prim_count = 0;
    const Triangle* triangles = nullptr;
    size_t triangle_count = 0;
};

inline DeviceCanonicalView canonical_view(const DeviceBvh& bvh, const Triangle* triangles, size_t triangle_count) {
    return {bvh.nodes.data(), static_cast<uint32_t>(bvh.nodes.size()), bvh.prim_indices.data(),
            bvh.prim_indices.size(), triangles, triangle_count};
}

// The host copy, for what needs the tree on the host (stats, refits).
inline Bvh download_bvh(const DeviceBvh& bvh) {
    Bvh out;
    out.nodes = download_all(bvh.nodes, bvh.nodes.size());
    out.prim_indices = download_all(bvh.prim_indices, bvh.prim_indices.size());
    return out;
}

inline void upload_bvh(const Bvh& bvh, DeviceBvh& out) {
    out.nodes.upload(bvh.nodes);
    out.prim_indices.upload(bvh.prim_indices);
}

// build_bvh_on_device with the tree kept on the device: the builders that
// emit on the device leave it there; a tree the host emitted or optimized
// (depth fallbacks, GridBvh, treelets, reinsertion, 0-1 triangles) is
// uploaded. stages->build_span_ms: one event pair around all of it.
inline DeviceBvh build_resident_bvh(std::span<const Triangle> triangles, const BuildOptions& options,
                                    DeviceBuildStages& stages, int device) {
    DeviceBvh out;
    EventTimer span;
    span.start();
    const Bvh host = build_bvh_on_device(triangles, options, &stages, device, &out);
    if (out.empty()) upload_bvh(host, out);
    stages.build_span_ms = span.stop_ms();
    return out;
}

}  // namespace rf::cuda
