// Internal face of the CUDA HLBVH2 (hlbvh2_build.cu): the raw tree as the
// device left it, for the GPU tests to check the forest, the cluster
// compaction, the top level and the device's level-wise boxes directly.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/hlbvh2_emit.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

struct DeviceHlbvh2Forest {
    Hlbvh2Forest forest;                   // empty arrays for n < 2; top_refs empty for 1 cluster
    std::vector<Box3f> cluster_boxes;      // per cluster, from the device's bottom-up pass
    std::vector<Box3f> top_boxes;          // per top node k, from the device's bottom-up pass
    std::vector<uint32_t> top_level_sizes; // tasks per top task-queue level, level 0 = the root
};

// leaf_size: 1 .. 64 (BuildOptions::max_leaf_size).
DeviceHlbvh2Forest build_hlbvh2_forest_on_device(std::span<const Triangle> triangles, uint32_t leaf_size,
                                                 DeviceBuildStages* stages = nullptr, int device = 0);

}  // namespace rf::cuda
