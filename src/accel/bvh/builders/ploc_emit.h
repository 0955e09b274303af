// The canonical BVH of a PLOC clustering (Meister and Bittner 2018) done
// elsewhere (the CUDA PLOC, backend/cuda/ploc_build.cu): the host half of
// the device build, the same refit and emitter as build_ploc's.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// `order`: sorted position -> triangle (the stable 63-bit Morton order);
// `children`: 2 (n - 1) child references of the nodes 0 .. n-2 in the order
// they were created (ploc_steps.h's compact_cluster writes them; the root is
// n - 2); `iteration_nodes`: the nodes each iteration created, in order
// (their sum is n - 1). A node's children are leaves or nodes of earlier
// iterations. Computes every node's box, count, SAH cost and leaf collapse,
// iteration by iteration, as build_ploc does, and emits the canonical BVH,
// which is then build_ploc's for the same clustering. Throws rf::Error when
// the arrays are inconsistent (sizes, a child not created before its parent).
Bvh emit_ploc_tree(std::span<const Triangle> triangles, const BvhBuildConfig& config, std::vector<uint32_t>&& order,
                   std::span<const uint32_t> children, std::span<const uint32_t> iteration_nodes);

}  // namespace rf
