// Internal face of the CUDA H-PLOC (hploc_build.cu): the clustering as the
// device left it, downloaded whole, for the GPU tests to check the device's
// nodes and their boxes directly.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "backend/cuda/device_builders.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Indexed as emit_hploc_tree (accel/bvh/builders/hploc.h) takes them; empty
// node arrays for n < 2. Node numbers follow the device's schedule (each
// node after its children), so they may differ from the CPU's; the tree
// they form does not.
struct DeviceHplocTree {
    std::vector<uint32_t> order;     // sorted position -> triangle
    std::vector<uint32_t> children;  // 2 (n - 1), root n - 2
    std::vector<Box3f> node_boxes;   // n - 1, as the merges wrote them
};

// radius: clamped to 1 .. 31 like build_hploc's.
DeviceHplocTree build_hploc_tree_on_device(std::span<const Triangle> triangles, int radius,
                                           DeviceBuildStages* stages = nullptr, int device = 0);

}  // namespace rf::cuda
