// Partial triangles for GridBvhSplit (Garanzha 2014, dissertation §4.4):
// large triangles become several references, each with the tight box of the
// part of the triangle between two split planes, under a hard budget.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "accel/bvh/builders/grid_bvh_sparse_grid.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::gridbvh {

// clip_triangle_to_box, the split request, share and parts of one
// reference: grid_bvh_steps.h (shared with the device).

// One reference per triangle, with the triangle's box.
std::vector<GridRef> make_triangle_refs(std::span<const Triangle> triangles);

// Splits references wider than scene extent / 128 (formula 4.1) into partial
// triangles in two passes (pass 1 along each reference's longest axis, pass 2
// again on the parts, possibly along another axis). At most
// floor(budget * triangles.size()) references are added in all. Split planes
// are Grid0 planes of `frame` nearest to equal parts.
std::vector<GridRef> split_into_partial_triangles(std::span<const Triangle> triangles, std::vector<GridRef> refs,
                                                  const GridFrame& frame, float budget);

}  // namespace rf::gridbvh
