// The always-resident levels of the paged scene: by default one wide BVH
// over the pages' bounds (TopLevel::WideBvh), or the seed's (Garanzha 2014,
// §6.3.1 (e)-(g)): a uniform top grid over the scene and, in every non-empty cell,
// a BVH over the bounds of the pages overlapping it, each clipped to the
// cell (isectAABB_i), with one page per leaf. A ray walks the grid with a
// 3D-DDA and can restart at any cell; the middle BVHs are cheap to re-walk.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "ooc/pack_format.h"
#include "rayforge/accel/bvh/bvh.h"

namespace rf::pack {

struct TopGrid {
    Box3f scene_bounds;                // union of the page bounds
    Box3f grid_bounds;                 // scene_bounds, padded
    int resolution[3] = {1, 1, 1};     // `cells_on_longest` on the longest axis, proportional on the others
    std::vector<uint32_t> cell_roots;  // x fastest; kEmptyCell or the cell's root in middle_nodes
    std::vector<BvhNode> middle_nodes; // every cell's BVH; leaves: first = reference, count = 1
};

// Over the world boxes of the top references (pack_format.h's TopRef).
TopGrid build_top_grid(std::span<const Box3f> ref_boxes, int cells_on_longest);


// Cells per axis for a box and a resolution on its longest axis.
void grid_resolution_for(const Box3f& box, int cells_on_longest, int out[3]);

}  // namespace rf::pack
