// Internal face of the CUDA PLOC (ploc_build.cu): the clustering as the
// device left it, downloaded whole, for the GPU tests to check the device's
// nodes, their boxes and the iteration sizes directly.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "backend/cuda/device_builders.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Indexed as in accel/bvh/builders/ploc_emit.h; empty node arrays for n < 2.
struct DevicePlocTree {
    std::vector<uint32_t> order;            // sorted position -> triangle
    std::vector<uint32_t> children;         // 2 (n - 1), nodes in creation order, root n - 2
    std::vector<uint32_t> iteration_nodes;  // nodes created per iteration
    std::vector<Box3f> node_boxes;          // n - 1, as the merges wrote them
};

// radius: clamped to 1 .. 2^16 like PlocOptions::radius.
DevicePlocTree build_ploc_tree_on_device(std::span<const Triangle> triangles, int radius,
                                         DeviceBuildStages* stages = nullptr, int device = 0);

}  // namespace rf::cuda
