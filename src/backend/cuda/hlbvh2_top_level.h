// Internal face of the CUDA HLBVH2's top level (hlbvh2_top_level.cu): the
// grid SAH over the cluster boxes (Garanzha 2014 ch. 5 over ch. 4 §4.3) by
// task queues on the device, called by hlbvh2_build.cu once the bottom
// levels and their boxes are final.
#pragma once

#include <cstdint>
#include <vector>

#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/device_buffer.h"
#include "rayforge/math/box.h"

namespace rf::cuda {

// Device arrays the top level reads (all final when it starts).
struct DeviceTopLevelInput {
    uint32_t n = 0;                           // triangles; top node k is node n - 1 + k
    uint32_t clusters = 0;                    // >= 2
    const uint32_t* cluster_begin = nullptr;  // clusters: first sorted position (the last ends at n)
    const uint32_t* cluster_prefix = nullptr; // clusters: 15-bit Morton prefix
    const Box3f* cluster_boxes = nullptr;     // clusters
    const uint32_t* cluster_roots = nullptr;  // clusters: bottom-tree root references
    hlbvh2::BoxView bottom{};                 // the bottom levels' boxes, for the top boxes
};

// What it leaves on the device (counted by the build's meter).
struct DeviceTopLevel {
    DeviceBuffer<uint32_t> top_refs;    // 2 (clusters - 1): 2 k + side
    DeviceBuffer<Box3f> top_boxes;      // clusters - 1
    std::vector<uint32_t> level_sizes;  // tasks (= top nodes) per task-queue level, level 0 = the root
};

// Builds the top level: the clusters as primitives and every task-queue
// level in ONE cooperative launch (per level, the large tasks a thread
// block each, the others kTopLanes threads per task, a grid sync between
// levels; the levels' sizes kept on the device, no host read per level),
// the same tree as the CPU's (build_hlbvh2_top_level), then the top nodes'
// boxes bottom-up in one launch with arrival counters (after one that links
// the parents). Sets stages.top_ms (the task-queue levels) and
// stages.top_levels (the levels, not launches), and adds the top boxes'
// time to stages.boxes_ms. Buffers are counted by build.meter; the queues
// are freed on return. Throws rf::Error on a device without cooperative
// launches.
DeviceTopLevel build_top_level_on_device(const DeviceTopLevelInput& in, BuildContext& build);

}  // namespace rf::cuda
