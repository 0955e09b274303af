// Per-triangle and per-cell steps of the uniform-grid build, written once for
// the CPU builder (uniform_grid.cpp) and the CUDA builder
// (backend/cuda/uniform_grid_build.cu), so both put every triangle into
// exactly the same cells:
//
//  - triangle_overlaps_cell_box(): Akenine-Möller's SAT triangle/box test
//    (Bogolepov et al., §2.1.2), in double.
//  - for_each_overlapped_cell(): the cells a triangle overlaps, cells
//    inflated by the build's margin: its bounds' cell range, then the SAT
//    test per cell; large well-shaped triangles walk columns along their
//    normal's dominant axis, where the plane spans only a couple of cells.
//  - The sort-based build of Kalojanov and Slusallek, "A Parallel Algorithm
//    for Construction of Uniform Grids" (HPG 2009), §3: a thread per triangle
//    counts its cells (count_overlapped_cells), a scan gives each triangle its
//    write offset, the thread writes its (cell, triangle) pairs
//    (write_cell_pairs), the pairs are radix-sorted by cell over
//    cell_key_bits() bits, and a thread per sorted pair marks where the cell
//    changes (cell_start_of). The sort is stable and the pairs are
//    written in triangle order, so each cell's triangles stay ascending:
//    the CPU builder's lists.
//  - chessboard_line_pass(): one cell of a 1D pass of the proximity-cloud
//    distance transform (Bogolepov et al., §2.1.4), the device's variant of
//    proximity_clouds.cpp (see the function's comment).
//
// Products go through dmul_rn() (core/rounded_arithmetic.h): nvcc would
// otherwise fuse a * b + c into one rounding (an FMA) where the host (built
// with -ffp-contract=off) rounds twice, and the grids would differ in the
// last bit of a plane test.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "accel/grid/uniform_grid.h"
#include "core/rounded_arithmetic.h"
#include "rayforge/core/host_device.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::uniform_grid_steps {

struct Vec3d {
    double x, y, z;
};

RF_HDI Vec3d to_vec3d(Vec3f v) { return {double(v.x), double(v.y), double(v.z)}; }
RF_HDI Vec3d operator-(Vec3d a, Vec3d b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
RF_HDI double dot(Vec3d a, Vec3d b) { return dmul_rn(a.x, b.x) + dmul_rn(a.y, b.y) + dmul_rn(a.z, b.z); }
RF_HDI Vec3d cross(Vec3d a, Vec3d b) {
    return {dmul_rn(a.y, b.z) - dmul_rn(a.z, b.y), dmul_rn(a.z, b.x) - dmul_rn(a.x, b.z),
            dmul_rn(a.x, b.y) - dmul_rn(a.y, b.x)};
}
// std::min / std::max exactly (the CPU builder's original choices).
RF_HDI double min_of(double a, double b) { return b < a ? b : a; }
RF_HDI double max_of(double a, double b) { return a < b ? b : a; }

// min(a, min(b, c)) and max(a, max(b, c)), nested in this order on both sides.
RF_HDI double min3(double a, double b, double c) {
    const double m = b < c ? b : c;
    return a < m ? a : m;
}
RF_HDI double max3(double a, double b, double c) {
    const double m = b > c ? b : c;
    return a > m ? a : m;
}

// The box's projection radius on `axis` for half-sizes h.
RF_HDI double projected_radius(Vec3d axis, Vec3d h) {
    return dmul_rn(h.x, fabs(axis.x)) + dmul_rn(h.y, fabs(axis.y)) + dmul_rn(h.z, fabs(axis.z));
}

// True when `axis` separates the box-centred triangle (v0, v1, v2) from the
// box of half-size h at the origin.
RF_HDI bool axis_separates(Vec3d axis, Vec3d v0, Vec3d v1, Vec3d v2, Vec3d h) {
    const double p0 = dot(axis, v0), p1 = dot(axis, v1), p2 = dot(axis, v2);
    const double r = projected_radius(axis, h);
    return min3(p0, p1, p2) > r || max3(p0, p1, p2) < -r;
}

// Triangle/box overlap by the separating axis theorem, after Akenine-Möller,
// "Fast 3D Triangle-Box Overlap Testing", JGT 6(1), 2001: a triangle and an
// axis-aligned box are disjoint iff one of 13 axes separates their
// projections (the 3 box face normals, the triangle normal, and the 9 cross
// products of a box axis with a triangle edge). In double, so the only slack
// that matters is the build's cell margin. Touching counts as overlap (all
// rejections are strict); a zero normal or edge gives a zero axis, which
// separates nothing, so a collinear triangle is tested as its segment and a
// point triangle as its point. True when triangle (a, b, c) and the box
// centre ± half overlap or touch.
RF_HDI bool triangle_overlaps_cell_box(Vec3d center, Vec3d half, Vec3d a, Vec3d b, Vec3d c) {
    const Vec3d v0 = a - center, v1 = b - center, v2 = c - center;
    // Box face normals: the triangle's bounds against the box.
    if (min3(v0.x, v1.x, v2.x) > half.x || max3(v0.x, v1.x, v2.x) < -half.x) return false;
    if (min3(v0.y, v1.y, v2.y) > half.y || max3(v0.y, v1.y, v2.y) < -half.y) return false;
    if (min3(v0.z, v1.z, v2.z) > half.z || max3(v0.z, v1.z, v2.z) < -half.z) return false;
    const Vec3d f[3] = {v1 - v0, v2 - v1, v0 - v2};
    // The triangle's plane.
    const Vec3d n = cross(f[0], f[1]);
    const double plane = dot(n, v0);
    const double r = projected_radius(n, half);
    if (plane > r || plane < -r) return false;
    // The 9 edge axes e_i x f_j.
    for (int j = 0; j < 3; ++j) {
        if (axis_separates({0.0, -f[j].z, f[j].y}, v0, v1, v2, half)) return false;
        if (axis_separates({f[j].z, 0.0, -f[j].x}, v0, v1, v2, half)) return false;
        if (axis_separates({-f[j].y, f[j].x, 0.0}, v0, v1, v2, half)) return false;
    }
    return true;
}

// What a thread needs of the grid: the boundary planes (grid_plane(), the
// traversal's own expression, widened to double), the layout and the margin.
struct CellGridView {
    const double* planes[3] = {nullptr, nullptr, nullptr};  // dims[a] + 1 planes per axis
    int dims[3] = {0, 0, 0};
    double origin[3] = {0.0, 0.0, 0.0};
    double cell_size = 0.0;
    double eps = 0.0;  // inflation of every cell
};

RF_HDI uint32_t cell_index(const CellGridView& g, int x, int y, int z) {
    return static_cast<uint32_t>(x) +
           static_cast<uint32_t>(g.dims[0]) * (static_cast<uint32_t>(y) + static_cast<uint32_t>(g.dims[1]) *
                                                                             static_cast<uint32_t>(z));
}

// The cell containing x by arithmetic, clamped; first_cell/last_cell correct it.
RF_HDI int estimate_cell(const CellGridView& g, int a, double x) {
    const double c = floor((x - g.origin[a]) / g.cell_size);
    const double top = double(g.dims[a] - 1);
    return static_cast<int>(c < 0.0 ? 0.0 : (top < c ? top : c));
}
// The first cell whose inflated box reaches x: planes[i + 1] + eps >= x.
RF_HDI int first_cell(const CellGridView& g, int a, double x) {
    const double* p = g.planes[a];
    int i = estimate_cell(g, a, x);
    while (i > 0 && p[i] + g.eps >= x) --i;
    while (i < g.dims[a] - 1 && p[i + 1] + g.eps < x) ++i;
    return i;
}
// The last cell whose inflated box starts at or below x: planes[i] - eps <= x.
RF_HDI int last_cell(const CellGridView& g, int a, double x) {
    const double* p = g.planes[a];
    int i = estimate_cell(g, a, x);
    while (i < g.dims[a] - 1 && p[i + 1] - g.eps <= x) ++i;
    while (i > 0 && p[i] - g.eps > x) --i;
    return i;
}

// The SAT test against cell (x, y, z) inflated by eps.
RF_HDI bool overlaps_cell(const CellGridView& g, Vec3d v0, Vec3d v1, Vec3d v2, int x, int y, int z) {
    const Vec3d lo{g.planes[0][x], g.planes[1][y], g.planes[2][z]};
    const Vec3d hi{g.planes[0][x + 1], g.planes[1][y + 1], g.planes[2][z + 1]};
    const Vec3d center{dmul_rn(0.5, lo.x + hi.x), dmul_rn(0.5, lo.y + hi.y), dmul_rn(0.5, lo.z + hi.z)};
    const Vec3d half{dmul_rn(0.5, hi.x - lo.x) + g.eps, dmul_rn(0.5, hi.y - lo.y) + g.eps,
                     dmul_rn(0.5, hi.z - lo.z) + g.eps};
    return triangle_overlaps_cell_box(center, half, v0, v1, v2);
}

// Calls visit(cell index) once for every cell the triangle overlaps, in a
// fixed order (the order matters to nobody: pairs are sorted by cell, and the
// CPU sorts its lists).
template <class Visit>
RF_HDI void for_each_overlapped_cell(const CellGridView& g, const Triangle& tri, Visit&& visit) {
    const Box3f bb = tri.bounds();
    int lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
        lo[a] = first_cell(g, a, bb.lo[a]);
        hi[a] = last_cell(g, a, bb.hi[a]);
        if (lo[a] > hi[a]) return;
    }
    const uint64_t box_cells = uint64_t(hi[0] - lo[0] + 1) * uint64_t(hi[1] - lo[1] + 1) * uint64_t(hi[2] - lo[2] + 1);
    if (box_cells == 1) {  // the triangle lies inside this one (inflated) cell
        visit(cell_index(g, lo[0], lo[1], lo[2]));
        return;
    }
    const Vec3d v0 = to_vec3d(tri.v0), v1 = to_vec3d(tri.v1), v2 = to_vec3d(tri.v2);
    const Vec3d e0 = v1 - v0, e1 = v2 - v0;
    const Vec3d n = cross(e0, e1);
    const bool well_shaped = dot(n, n) > dmul_rn(dmul_rn(1e-12, dot(e0, e0)), dot(e1, e1));
    if (box_cells <= 8 || !well_shaped) {
        // Small boxes, and (near-)degenerate triangles whose plane is unreliable.
        for (int z = lo[2]; z <= hi[2]; ++z)
            for (int y = lo[1]; y <= hi[1]; ++y)
                for (int x = lo[0]; x <= hi[0]; ++x)
                    if (overlaps_cell(g, v0, v1, v2, x, y, z)) visit(cell_index(g, x, y, z));
        return;
    }
    const double na[3] = {fabs(n.x), fabs(n.y), fabs(n.z)};
    const int k = na[0] >= na[1] && na[0] >= na[2] ? 0 : (na[1] >= na[2] ? 1 : 2);
    const int i_axis = k == 0 ? 1 : 0, j_axis = k == 2 ? 1 : 2;
    const double nv[3] = {n.x, n.y, n.z};
    const double d = dot(n, v0);
    int cell[3];
    for (int ci = lo[i_axis]; ci <= hi[i_axis]; ++ci) {
        for (int cj = lo[j_axis]; cj <= hi[j_axis]; ++cj) {
            // The plane's k-range over this column (inflated), clipped to the bounds.
            const double xs[2] = {g.planes[i_axis][ci] - g.eps, g.planes[i_axis][ci + 1] + g.eps};
            const double ys[2] = {g.planes[j_axis][cj] - g.eps, g.planes[j_axis][cj + 1] + g.eps};
            double kmin = __builtin_huge_val(), kmax = -kmin;
            for (int xi = 0; xi < 2; ++xi) {
                for (int yi = 0; yi < 2; ++yi) {
                    const double pk = (d - dmul_rn(nv[i_axis], xs[xi]) - dmul_rn(nv[j_axis], ys[yi])) / nv[k];
                    kmin = min_of(kmin, pk);
                    kmax = max_of(kmax, pk);
                }
            }
            const double slack = dmul_rn(1e-9, fabs(kmin) + fabs(kmax));
            kmin = max_of(kmin - slack, double(bb.lo[k]));
            kmax = min_of(kmax + slack, double(bb.hi[k]));
            if (kmin > kmax) continue;
            const int first = first_cell(g, k, kmin), last = last_cell(g, k, kmax);
            const int k_lo = lo[k] < first ? first : lo[k];
            const int k_hi = last < hi[k] ? last : hi[k];
            cell[i_axis] = ci;
            cell[j_axis] = cj;
            for (int ck = k_lo; ck <= k_hi; ++ck) {
                cell[k] = ck;
                if (overlaps_cell(g, v0, v1, v2, cell[0], cell[1], cell[2])) visit(cell_index(g, cell[0], cell[1], cell[2]));
            }
        }
    }
}

// ------------------------------------------------ Kalojanov-Slusallek pairs

// Step 1: a thread per triangle counts its (cell, triangle) pairs.
RF_HDI uint32_t count_overlapped_cells(const CellGridView& g, const Triangle& tri) {
    uint32_t count = 0;
    for_each_overlapped_cell(g, tri, [&](uint32_t) { ++count; });
    return count;
}

// Step 3: the thread writes its pairs from its scanned offset on.
RF_HDI void write_cell_pairs(const CellGridView& g, const Triangle& tri, uint32_t triangle, uint32_t offset,
                             uint32_t* pair_cells, uint32_t* pair_triangles) {
    for_each_overlapped_cell(g, tri, [&](uint32_t cell) {
        pair_cells[offset] = cell;
        pair_triangles[offset] = triangle;
        ++offset;
    });
}

// Step 4: the radix sort's key bits: enough for the largest cell index
// (at least 1, so that the sort has something to do).
RF_HDI int cell_key_bits(uint64_t cell_count) {
    int bits = 1;
    while (bits < 32 && (uint64_t{1} << bits) < cell_count) ++bits;
    return bits;
}

// Step 5: thread c of cells 0..cell_count: cell c's start is the number of
// sorted pairs in cells before c (a binary search), which is the CPU's
// prefix-sum convention (an empty cell starts where the next non-empty one
// does; cell_start[cell_count] = pairs). One thread per cell keeps the work
// even however sparse the grid is.
RF_HDI uint32_t cell_start_of(const uint32_t* sorted_cells, uint32_t pairs, uint64_t cell) {
    uint32_t lo = 0, hi = pairs;  // the first pair whose cell is >= cell
    while (lo < hi) {
        const uint32_t mid = lo + (hi - lo) / 2;
        if (uint64_t{sorted_cells[mid]} < cell) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

// ------------------------------------------------ proximity clouds

// Distances saturate here: the grid stores bytes.
inline constexpr uint32_t kProximityCap = 255;

// The initial map of the distance transform: 0 on non-empty cells, the cap elsewhere.
RF_HDI uint8_t occupancy_distance(const uint32_t* cell_start, uint64_t cell) {
    return cell_start[cell + 1] > cell_start[cell] ? uint8_t{0} : uint8_t(kProximityCap);
}

// One cell of a 1D pass of the Chebyshev distance transform along a line of
// n cells `stride` apart: min(cap, min_j max(|i - j|, g[j])). Three passes
// (x, y, z) give the 3D L-inf distance, as in proximity_clouds.cpp
// (max(a, max(b, c)) = max(max(a, b), c)); clamping at the cap between passes
// is exact since min(max(a, min(b, C)), C) = min(max(a, b), C). Where the CPU
// runs Meijster's lower-envelope scan per line (O(n), with scratch), a thread
// per cell searches outwards from i: the candidates at radius r are >= r, so
// the search stops once r reaches the best so far, at most `cap` steps, and
// needs no scratch memory. Neighbouring threads read neighbouring lines.
RF_HDI uint8_t chessboard_line_pass(const uint8_t* g, uint64_t stride, uint32_t n, uint32_t i) {
    uint32_t best = g[i * stride];
    for (uint32_t r = 1; r < best; ++r) {
        const bool below = i >= r, above = i + r < n;
        if (!below && !above) break;
        if (below) {
            const uint32_t v = g[(i - r) * stride];
            const uint32_t candidate = v > r ? v : r;
            best = candidate < best ? candidate : best;
        }
        if (above) {
            const uint32_t v = g[(i + r) * stride];
            const uint32_t candidate = v > r ? v : r;
            best = candidate < best ? candidate : best;
        }
    }
    return static_cast<uint8_t>(best);
}

// The pass along `axis` for cell `cell` of a grid of dims (x fastest): reads
// the map `in`, returns the cell's new distance.
RF_HDI uint8_t chessboard_pass_at(const uint8_t* in, const int* dims, int axis, uint64_t cell) {
    const uint64_t nx = uint64_t(dims[0]), ny = uint64_t(dims[1]);
    const uint64_t coord[3] = {cell % nx, (cell / nx) % ny, cell / (nx * ny)};
    const uint64_t stride = axis == 0 ? 1 : (axis == 1 ? nx : nx * ny);
    const uint64_t i = coord[axis];
    return chessboard_line_pass(in + (cell - i * stride), stride, static_cast<uint32_t>(dims[axis]),
                                static_cast<uint32_t>(i));
}

// ------------------------------------------------ host side
// Defined in uniform_grid.cpp, so that both builders use the library's one
// copy, compiled without contraction (-ffp-contract=off), and agree to the bit.

// The margin added to every cell of `layout` (uniform_grid.cpp says why).
double cell_inflation(const GridLayout& layout);

// The boundary planes of a layout (grid_plane(), widened to double), all
// three axes in one array (x, then y, then z) so that the device copies them
// in one transfer.
struct CellPlanes {
    std::vector<double> values;
    size_t offset[3] = {0, 0, 0};

    explicit CellPlanes(const GridLayout& layout);
    // The view over a copy of `values` at `base` (host or device memory).
    [[nodiscard]] CellGridView view(const GridLayout& layout, double eps, const double* base) const {
        CellGridView g;
        for (int a = 0; a < 3; ++a) {
            g.planes[a] = base + offset[a];
            g.dims[a] = layout.dims[a];
            g.origin[a] = double(layout.origin[a]);
        }
        g.cell_size = double(layout.cell_size);
        g.eps = eps;
        return g;
    }
};

}  // namespace rf::uniform_grid_steps
