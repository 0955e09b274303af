// GridBvh and GridBvhSplit builders (Garanzha 2014, dissertation ch. 4):
// SAH over a sparse hierarchical grid, optionally with partial triangles;
// produce the canonical rf::Bvh.
#pragma once

#include <cstddef>
#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Stage breakdown of one build (milliseconds and sizes), in the spirit of the
// dissertation's table 4.1.
struct GridBvhStages {
    double partial_triangles_ms = 0.0;  // §4.4: references and their splitting (GridBvhSplit)
    double sort_ms = 0.0;               // §4.2 step 3: sorting references by Grid0 cell key
    double grid0_ms = 0.0;              // §4.2 steps 4-5: TopGrid0 and the 8^3 bottom grids
    double coarse_levels_ms = 0.0;      // §4.2 step 6: count-only levels of detail
    double hierarchy_ms = 0.0;          // §4.3 Algorithm 4.1 EmitHierarchy (split tasks)
    double leaf_finish_ms = 0.0;        // gathering leaf references, splitting large leaves
    double emission_ms = 0.0;           // bounding boxes and canonical depth-first layout
    double total_ms = 0.0;
    size_t triangles = 0;
    size_t references = 0;              // partial triangles (== triangles without splitting)
    size_t occupied_top_cells = 0;      // non-empty cells of TopGrid0 (128^3)
    size_t grid_bytes = 0;              // memory of the sparse grid and its levels
    size_t hierarchy_leaves = 0;        // leaves of the grid hierarchy, before finishing
    size_t large_leaves = 0;            // of those, leaves with more than max_leaf_size references
};

// Builds over `triangles` with config's max_leaf_size and SAH costs (leaf
// finishing) and, when `partial_triangles` is set, grid_bvh.split_budget (at
// most floor(split_budget * triangles) extra references). The result is the
// same for every thread count; no triangles give an empty Bvh. Throws
// rf::Error when an allocation exceeds the memory budget.
Bvh build_grid_bvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, const GridBvhOptions& grid_bvh,
                   bool partial_triangles);
// The same, also reporting the stage breakdown when `stages` is not null.
Bvh build_grid_bvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, const GridBvhOptions& grid_bvh,
                   bool partial_triangles, GridBvhStages* stages);

}  // namespace rf
