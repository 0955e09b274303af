// Internal face of the CUDA LBVH (lbvh_build.cu): the raw Karras radix tree
// as the device left it, downloaded whole, for the GPU tests to check the
// device's inner nodes, parent links, arrival counters and boxes directly.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "backend/cuda/device_builders.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Indexed as in accel/bvh/builders/karras_tree_steps.h; empty arrays for n < 2.
struct DeviceKarrasTree {
    std::vector<uint32_t> order;         // sorted position -> triangle
    std::vector<uint32_t> children;      // 2 (n - 1)
    std::vector<uint32_t> inner_parent;  // n - 1
    std::vector<uint32_t> leaf_parent;   // n
    std::vector<uint32_t> arrivals;      // n - 1: 2 each after the box pass
    std::vector<Box3f> inner_boxes;      // n - 1
    std::vector<Box3f> triangle_boxes;   // n, per triangle
};

DeviceKarrasTree build_karras_tree_on_device(std::span<const Triangle> triangles, int morton_bits,
                                             DeviceBuildStages* stages = nullptr, int device = 0);

}  // namespace rf::cuda
