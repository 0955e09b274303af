// Binned SAH builder (Wald 2007, "On fast Construction of SAH-based Bounding
// Volume Hierarchies"), producing the canonical rf::Bvh.
#pragma once

#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Builds over `triangles` with config's max_leaf_size and SAH costs and
// binned.bin_count (assumed validated, see build_accel). The result is the
// same for every thread count: nodes in depth-first order, siblings adjacent,
// every root-to-leaf path at most kBvhMaxDepth (64) inner nodes. No triangles
// give an empty Bvh (no nodes).
Bvh build_binned_sah(std::span<const Triangle> triangles, const BvhBuildConfig& config, const BinnedSahOptions& binned);

}  // namespace rf
