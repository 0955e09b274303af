// The canonical BVH of a Karras 2012 radix tree built elsewhere (the CUDA
// LBVH, backend/cuda/lbvh_build.cu): the host half of the device build.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// `order`: sorted position -> triangle (the stable Morton order);
// `children`: 2 (n - 1) child references of inner nodes 0 .. n-2 (root 0) as
// karras::build_inner writes them. Computes every inner node's box, count,
// SAH cost and leaf collapse (as build_lbvh does) and emits the canonical
// BVH, which is then build_lbvh's on the same order and tree.
Bvh emit_karras_tree(std::span<const Triangle> triangles, const BvhBuildConfig& config, std::vector<uint32_t>&& order,
                     std::span<const uint32_t> children);

}  // namespace rf
