// Post-build BVH optimizer by reinsertion (Meister and Bittner 2018 /
// Bittner et al. 2013): moves subtrees to where they lower the SAH cost.
#pragma once

#include <span>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

void optimize_reinsertion(Bvh& bvh, std::span<const Triangle> triangles, const BuildOptions& options);

}  // namespace rf
