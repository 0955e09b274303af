// PLOC builder (Meister and Bittner 2018, "Parallel Locally-Ordered
// Clustering for Bounding Volume Hierarchy Construction"), producing the
// canonical rf::Bvh.
#pragma once

#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

Bvh build_ploc(std::span<const Triangle> triangles, const BvhBuildConfig& config, const PlocOptions& ploc_options);

}  // namespace rf
