// Uniform grid over triangles (Bogolepov et al., §2.1.2; Zlatuška 2009,
// §4.2.1): cubic cells, each cell's triangle list stored compactly as offsets
// into one flat array of triangle indices (Zlatuška 2009's "count and offset"
// per cell; a triangle in several cells is referenced several times).
//
// Resolution: `resolution` cells on the longest axis, or Zlatuška 2009's rule
// (after Purcell) for resolution 0: floor(4 * n^(1/4)) cells on the shortest
// axis of non-zero extent, cubic cells. The automatic rule is capped at 8 times
// the cell count of a cubic scene, so that a long thin scene does not explode.
// Triangles go into every cell they overlap by Akenine-Möller's SAT test
// (Bogolepov et al.), with cells inflated by a small margin (see grid_traversal.h).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/grid_traversal.h"

namespace rf {

// Where the cells are: origin, cubic cell size, cells per axis (all 0 when empty).
struct GridLayout {
    Vec3f origin;
    float cell_size = 0.0f;
    std::array<int, 3> dims{0, 0, 0};
    [[nodiscard]] size_t cell_count() const {
        return static_cast<size_t>(dims[0]) * static_cast<size_t>(dims[1]) * static_cast<size_t>(dims[2]);
    }
};

// Chooses the layout over `bounds` (the triangles' bounds) for `triangle_count`
// triangles; resolution 0 = Zlatuška 2009's rule. The grid box contains `bounds`
// with a margin on every side. Throws rf::Error for non-finite bounds or more
// cells than 32-bit cell indices allow.
GridLayout choose_grid_layout(const Box3f& bounds, size_t triangle_count, int resolution);

struct UniformGrid {
    GridLayout layout;
    double inflation = 0.0;             // margin added to every cell during the build
    std::vector<uint32_t> cell_start;   // cell_count() + 1 offsets into cell_prims
    std::vector<uint32_t> cell_prims;   // triangle indices, grouped by cell, ascending within a cell
    std::vector<uint8_t> proximity;     // empty, or per cell min(Chebyshev distance to a non-empty cell, 255)

    [[nodiscard]] size_t cell_count() const { return layout.cell_count(); }
    [[nodiscard]] size_t non_empty_cells() const;
    [[nodiscard]] size_t memory_bytes() const;
    // The cell box along one axis: [plane(i), plane(i + 1)] (no inflation).
    [[nodiscard]] Box3f cell_box(int x, int y, int z) const;
    [[nodiscard]] GridView view(const Triangle* triangles) const;
};

// Builds the grid in parallel (count pass, prefix sum, fill pass) and, with
// `proximity_clouds`, the distance map. Throws rf::Error when the cells or the
// references do not fit 32-bit offsets or the memory budget.
UniformGrid build_uniform_grid(std::span<const Triangle> triangles, int resolution, bool proximity_clouds);

}  // namespace rf
