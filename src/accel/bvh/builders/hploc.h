// H-PLOC builder (Benthin, Meister, Barczak, Mohan and Vaidyanathan 2024,
// "H-PLOC: Hierarchical Parallel Locally-Ordered Clustering for Bounding
// Volume Hierarchy Construction", HPG 2024), producing the canonical rf::Bvh.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// The search radius is PlocOptions::radius, clamped to 1 .. 31 (a range's
// clusters fit one 32-lane warp).
Bvh build_hploc(std::span<const Triangle> triangles, const BvhBuildConfig& config, const PlocOptions& ploc_options);

// The canonical BVH of an H-PLOC clustering done elsewhere (the CUDA
// builder, backend/cuda/hploc_build.cu; the tests' replays of it): `order`:
// sorted position -> triangle (the stable 63-bit Morton order); `children`:
// 2 (n - 1) child references (inner node, or kLeafRef | sorted position) of
// nodes 0 .. n-2, each node numbered after its children, the root n - 2.
// Finalizes the nodes in that order and emits as build_hploc does, so the
// BVH is build_hploc's for the same clustering. Throws rf::Error when the
// arrays do not form such a tree.
Bvh emit_hploc_tree(std::span<const Triangle> triangles, const BvhBuildConfig& config, std::vector<uint32_t>&& order,
                    std::span<const uint32_t> children);

}  // namespace rf
