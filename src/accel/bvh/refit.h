// Bottom-up refit of the canonical BVH and of the wide layouts: every box
// recomputed from the triangles' current positions, the topology kept
// (refit.cpp; the per-item steps in refit_steps.h, shared with the CUDA
// refit of backend/cuda/bvh_refit.cu).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/layout/wide_bvh.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// What a refit needs besides the tree, computed once per topology: each
// node's parent, the leaves, and the arrival counters (zero between passes).
struct RefitPlan {
    std::vector<uint32_t> parents;   // per node; refit::kNoParent for the root
    std::vector<uint32_t> leaves;    // node indices of the leaves, in node order
    std::vector<uint32_t> arrivals;  // per node
};

// The plan of `bvh`'s topology (parallel over nodes). Every node must be
// reachable from the root (a tree with free slots in its node array, as
// adapt's memory manager keeps, needs its own refit).
RefitPlan make_refit_plan(const Bvh& bvh);

// Recomputes every node box of `bvh` from `triangles` (the ones its
// prim_indices index, moved), in parallel, one leaf per item climbing with
// arrival counters. Boxes are bit-identical to refit_bvh_serial's.
void refit_bvh(Bvh& bvh, std::span<const Triangle> triangles);
// The same with a plan made for bvh's topology (reused frame after frame).
void refit_bvh(Bvh& bvh, std::span<const Triangle> triangles, RefitPlan& plan);
// The reference: one thread, children before parents.
void refit_bvh_serial(Bvh& bvh, std::span<const Triangle> triangles);

// Refits a wide layout collapsed from a BVH over `triangles` in place (no
// array is reallocated, so views of it stay valid): the triangle packs'
// coordinates rewritten as collapse_bvh writes them (NaN for zero-area
// triangles), every child box recomputed bottom-up, coord_scale updated
// (a view holding a copy of it must be refreshed).
template <int N>
void refit_wide_bvh(WideBvh<N>& wide, std::span<const Triangle> triangles);

extern template void refit_wide_bvh<4>(WideBvh<4>&, std::span<const Triangle>);
extern template void refit_wide_bvh<8>(WideBvh<8>&, std::span<const Triangle>);

}  // namespace rf
