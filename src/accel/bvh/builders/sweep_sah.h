// Full sweep SAH builder: every primitive boundary along each axis is a
// candidate split (centroids sorted per axis), producing the canonical rf::Bvh.
#pragma once

#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

Bvh build_sweep_sah(std::span<const Triangle> triangles, const BvhBuildConfig& config);

}  // namespace rf
