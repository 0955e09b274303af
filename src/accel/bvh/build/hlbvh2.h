// HLBVH2 builder (Garanzha 2014, dissertation ch. 5): 30-bit Morton codes,
// 15-bit clusters, bottom levels by binary search on Morton bits, top level
// over the cluster boxes by the grid SAH; produces the canonical rf::Bvh.
#pragma once

#include <span>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

Bvh build_hlbvh2(std::span<const Triangle> triangles, const BuildOptions& options);

}  // namespace rf
