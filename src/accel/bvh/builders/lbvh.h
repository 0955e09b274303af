// LBVH builder (Karras 2012, "Maximizing Parallelism in the Construction of
// BVHs, Octrees, and k-d Trees"), 30- or 63-bit Morton codes, producing the
// canonical rf::Bvh.
#pragma once

#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

Bvh build_lbvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, int morton_bits);

}  // namespace rf
