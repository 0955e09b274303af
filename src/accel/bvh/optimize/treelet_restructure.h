// Post-build BVH optimizer by treelet restructuring (Karras and Aila 2013,
// "Fast Parallel Construction of High-Quality Bounding Volume Hierarchies",
// HPG 2013): small treelets re-linked to their SAH-optimal topology,
// bottom up, in rounds. The per-node steps are treelet_restructure_steps.h,
// shared with the device pass (backend/cuda/treelet_restructure.cu).
#pragma once

#include <cstdint>
#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "accel/bvh/builders/raw_tree_emit_steps.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Runs options.rounds rounds whatever options.enabled says (the caller
// decides whether to run it). Any builder's tree: leaves stay whole (their
// boxes too, clipped ones included), subtrees of at most
// config.max_leaf_size primitives may collapse into one leaf where the SAH
// prefers it; the result is in canonical order and replaces `bvh` only when
// its SAH cost (config.sah) is not higher. The same tree for any thread count.
// Throws rf::Error for options out of range, a leaf of more than 255
// primitives or a primitive index outside `triangles`.
void optimize_treelets(Bvh& bvh, std::span<const Triangle> triangles, const BvhBuildConfig& config,
                       const TreeletOptions& options);

// Shared with the device pass.
namespace treelet {

// The smallest subtree (in primitives) restructured in round `round`
// (from 0): gamma = n, doubled every round (the paper's §5).
uint32_t round_gamma(const TreeletOptions& options, int round);
raw_emit::Costs emit_costs(const BvhBuildConfig& config);
// Throws rf::Error for what optimize_treelets rejects.
void check_input(const Bvh& bvh, std::span<const Triangle> triangles, const TreeletOptions& options);
// The canonical BVH of the restructured topology (`raw_children`, 2 per node
// of `input`, treelet::raw_children's encoding) over input's leaves, by the
// Morton builders' emitter: collapse where the SAH prefers it, the depth
// limit, depth-first order.
Bvh emit_restructured(const Bvh& input, std::span<const Triangle> triangles, const BvhBuildConfig& config,
                      std::span<const uint32_t> raw_children);
// Moves `optimized` into `bvh` when its SAH cost is not higher.
void keep_if_not_worse(Bvh& bvh, Bvh&& optimized, const SahCosts& sah);

}  // namespace treelet
}  // namespace rf
