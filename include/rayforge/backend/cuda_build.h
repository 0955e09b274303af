// Acceleration-structure builders on the CUDA device (issue 7), with the
// per-stage timing and peak device memory of each build. Available with
// rayforge::rayforge_cuda; no CUDA header is needed to use it.
#pragma once

#include <cstddef>
#include <span>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Milliseconds per stage of a device build. Device stages are timed with
// CUDA events around their kernels; transfers and host work are separate.
struct DeviceBuildStages {
    double upload_ms = 0.0;       // triangles to the device
    double bounds_ms = 0.0;       // per-triangle boxes and the centroid bounds reduction
    double morton_ms = 0.0;       // Morton codes
    double sort_ms = 0.0;         // radix sort of (code, triangle) pairs
    double inner_nodes_ms = 0.0;  // Karras's inner-node construction
    double boxes_ms = 0.0;        // bottom-up boxes with atomic counters
    double download_ms = 0.0;     // the raw tree back to the host
    double emit_ms = 0.0;         // host: leaf collapse and canonical emission
    size_t peak_device_bytes = 0; // sum of the live device buffers at the peak
    // HLBVH2 only (zero for LBVH):
    double clusters_ms = 0.0;     // compaction of runs of equal 15-bit prefixes, the level-0 tasks
    double bottom_ms = 0.0;       // bottom levels by work queues, one launch per level (boxes_ms: their boxes)
    double top_ms = 0.0;          // top level over the cluster boxes, on the host for now ("top (host)")
    uint32_t cluster_count = 0;   // clusters (bottom trees)
    uint32_t bottom_levels = 0;   // work-queue launches of the bottom levels

    // The build on the device alone: bounds + morton + sort + inner nodes
    // (LBVH) or clusters + bottom levels (HLBVH2) + boxes.
    [[nodiscard]] double device_total_ms() const {
        return bounds_ms + morton_ms + sort_ms + inner_nodes_ms + clusters_ms + bottom_ms + boxes_ms;
    }
};

// LBVH (Karras 2012) on device `device`: the same BVH as rf::build_lbvh with
// the same options and Morton bits (30 or 63): same nodes, same primitive
// order. The device computes boxes, codes, the sort, the radix tree and its
// boxes; the host collapses leaves by the SAH and writes the canonical layout.
// Throws rf::Error for invalid bits or CUDA failures (out of memory names the buffer).
Bvh build_lbvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options, int morton_bits,
                         DeviceBuildStages* stages = nullptr, int device = 0);

// HLBVH2 (Garanzha, Pantaleoni and McAllister 2011; Garanzha 2014 ch. 5) on
// device `device`: the same BVH as rf::build_hlbvh2 with the same options.
// The device sorts 30-bit codes once, compacts the 15-bit clusters and
// builds the bottom levels by work queues, with their boxes level by level;
// the host builds the top level over the clusters (the CPU's grid SAH: the
// device top level is not written yet) and writes the canonical layout.
// 0 and 1 triangles are handled on the host. Throws rf::Error for CUDA
// failures (out of memory names the buffer).
Bvh build_hlbvh2_on_device(std::span<const Triangle> triangles, const BuildOptions& options,
                           DeviceBuildStages* stages = nullptr, int device = 0);

}  // namespace rf::cuda
