// SBVH builder (Stich, Friedrich, Dietrich 2009, "Spatial Splits in Bounding
// Volume Hierarchies"), producing the canonical rf::Bvh (triangles may be
// referenced from several leaves).
#pragma once

#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

Bvh build_sbvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, const SbvhOptions& sbvh);

}  // namespace rf
