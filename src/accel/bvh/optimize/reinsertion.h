// Post-build BVH optimizer by reinsertion (Meister and Bittner 2018 /
// Bittner et al. 2013): moves subtrees to where they lower the SAH cost.
#pragma once

#include <span>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Runs reinsertion.iterations batches (0: until a batch gains too little),
// whatever reinsertion.enabled says; the caller decides whether to run it.
void optimize_reinsertion(Bvh& bvh, std::span<const Triangle> triangles, const SahCosts& sah,
                          const ReinsertionOptions& reinsertion);

}  // namespace rf
