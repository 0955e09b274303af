// GridBvh and GridBvhSplit builders (Garanzha 2014, dissertation ch. 4):
// SAH over a sparse hierarchical grid, optionally with partial triangles;
// produce the canonical rf::Bvh.
#pragma once

#include <span>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

Bvh build_grid_bvh(std::span<const Triangle> triangles, const BuildOptions& options, bool partial_triangles);

}  // namespace rf
