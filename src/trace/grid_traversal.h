// Closest-hit and any-hit traversal of a uniform grid: the 3D-DDA of
// Amanatides and Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing"
// (1987), as used by Bogolepov et al. (§2.1.3) and Zlatuška 2009 (§4.3.1.1),
// plus the proximity-cloud skipping of Bogolepov et al. (§2.1.5). Written
// once for the host and the CUDA backend: the grid is passed as raw pointers
// (GridView).
//
// Robustness choices (why the code differs from the papers' pseudocode):
//  - Cell boundaries are the float planes origin + i * cell_size, and every
//    crossing distance is recomputed from its plane, (plane - org) / dir,
//    instead of accumulating t += delta: no drift over thousands of cells,
//    and the start cell is chosen to agree with those same plane distances.
//    The build inflates every cell by a margin, so a triangle within rounding
//    of a boundary is in the cells on both sides.
//  - Zlatuška 2009's false-hit rule (a hit outside the current cell must not end
//    the walk) is kept in its stronger form: the closest hit found so far is
//    remembered and shrinks the ray's interval; the walk stops only once the
//    next cell starts beyond it (with a few ulps of slack). A hit beyond the
//    current cell therefore never terminates the walk early, and is not lost
//    either when its cell is never reached because of rounding.
//  - The walk starts from the ray's entry point into the grid, computed in
//    double, so that a far-away origin does not shift it sideways.
//  - Zero (or denormal, with infinite reciprocal) direction components never
//    step along their axis; an all-zero direction misses.
//  - Proximity clouds: an empty cell with distance D >= 2 has only empty cells
//    in the cube of radius D - 1 around it, so the ray jumps to where it leaves
//    that cube and the DDA state is re-derived there (one step, no triangle
//    tests). D = 1 is an ordinary DDA step.
#pragma once

#include <cmath>
#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/triangle_intersect.h"

namespace rf {

// A uniform grid as the traversal sees it; dims[0] == 0 is the empty grid
// (every ray misses). Cell (x, y, z) has index x + dims[0] * (y + dims[1] * z);
// its triangles are cell_prims[cell_start[c] .. cell_start[c + 1]).
struct GridView {
    const uint32_t* cell_start = nullptr;  // cell count + 1 offsets
    const uint32_t* cell_prims = nullptr;  // triangle indices, grouped by cell
    const uint8_t* proximity = nullptr;    // per cell Chebyshev distance to a non-empty cell (saturated); null = plain grid
    const Triangle* triangles = nullptr;
    Vec3f origin;                          // low corner of cell (0, 0, 0)
    float cell_size = 0.0f;                // cubic cells
    float inv_cell_size = 0.0f;
    int dims[3] = {0, 0, 0};
};

// The boundary plane i (0..dims[axis]) along `axis`. Build and traversal both
// use exactly this expression, so they agree on every boundary.
RF_HDI float grid_plane(const GridView& grid, int axis, int i) {
    return grid.origin[axis] + static_cast<float>(i) * grid.cell_size;
}

// Work done by one traversal (filled by the counting variants; accumulated).
struct GridTraversalCounters {
    uint32_t cells_visited = 0;  // DDA steps; a proximity jump counts as one
    uint32_t prims_tested = 0;   // triangle tests
};

namespace detail {

// Relative slack on distances compared against the ray's (shrinking) tmax:
// 1 + 2 * gamma(3), as for the BVH's slab test.
inline constexpr float kGridSlack = 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);

// The last triangles tested by a ray (a power of two); small, so that it
// stays in registers on the GPU.
inline constexpr int kGridMailboxSize = 8;

RF_HDI float grid_widen(float t) { return t + fabsf(t) * kGridSlack; }

// Per-ray DDA constants.
struct GridRay {
    float org[3];
    float dir[3];
    float inv_dir[3];
    int step[3];  // -1, 0 (never moves along this axis) or +1
};

RF_HDI float plane_distance(const GridView& g, const GridRay& r, int axis, int i) {
    return (grid_plane(g, axis, i) - r.org[axis]) * r.inv_dir[axis];
}

// The cell along `axis` that the ray is in at distance t (moving axes only),
// consistent with plane_distance: starts from a floor estimate, then moves
// until the cell's plane interval contains t (clamped to the grid).
RF_HDI int cell_at(const GridView& g, const GridRay& r, int axis, float t) {
    const int n = g.dims[axis];
    const float p = r.org[axis] + r.dir[axis] * t;
    float estimate = floorf((p - g.origin[axis]) * g.inv_cell_size);
    estimate = fminf(fmaxf(estimate, 0.0f), static_cast<float>(n - 1));  // fmaxf drops a NaN
    int c = static_cast<int>(estimate);
    if (r.step[axis] > 0) {
        while (c < n - 1 && plane_distance(g, r, axis, c + 1) <= t) ++c;
        while (c > 0 && plane_distance(g, r, axis, c) > t) --c;
    } else {
        while (c > 0 && plane_distance(g, r, axis, c) <= t) --c;
        while (c < n - 1 && plane_distance(g, r, axis, c + 1) > t) ++c;
    }
    return c;
}

// Distance at which the ray leaves cell c along a moving axis.
RF_HDI float cell_exit(const GridView& g, const GridRay& r, int axis, int c) {
    return plane_distance(g, r, axis, r.step[axis] > 0 ? c + 1 : c);
}

template <bool kAnyHit, bool kCount>
RF_HDI Hit grid_traverse(const GridView& g, const Ray& ray, GridTraversalCounters* counters) {
    Hit hit;
    if (g.dims[0] == 0) return hit;

    // Setup: per-axis steps and the ray's interval inside the grid box.
    GridRay r;
    float t_enter = ray.tmin;
    float t_leave = kInfinity;
    bool moving = false;
    for (int a = 0; a < 3; ++a) {
        r.org[a] = ray.org[a];
        r.dir[a] = ray.dir[a];
        const float inv = 1.0f / ray.dir[a];
        if (ray.dir[a] == 0.0f || !is_finite(inv)) {
            r.step[a] = 0;
            r.inv_dir[a] = 0.0f;
            // Parallel to this axis' slabs: inside them or never in the grid
            // (also rejects a NaN origin).
            if (!(r.org[a] >= grid_plane(g, a, 0) && r.org[a] <= grid_plane(g, a, g.dims[a]))) return hit;
            continue;
        }
        moving = true;
        r.step[a] = ray.dir[a] > 0.0f ? 1 : -1;
        r.inv_dir[a] = inv;
        const float t_lo = plane_distance(g, r, a, r.step[a] > 0 ? 0 : g.dims[a]);
        const float t_hi = plane_distance(g, r, a, r.step[a] > 0 ? g.dims[a] : 0);
        t_enter = fmaxf(t_enter, t_lo);
        t_leave = fminf(t_leave, t_hi);
    }
    float t_limit = ray.tmax;  // shrinks to the closest hit so far
    if (!moving || !(t_enter <= t_leave) || !(t_enter <= t_limit)) return hit;

    // Rebase the walk at the entry point, computed in double: from here on
    // crossing distances are (plane - entry) / dir, accurate to the grid's
    // size instead of to the distance of a far-away origin (whose rounding
    // would shift the walked line sideways by more than the cells' margin).
    // Walk distances are relative to `base`; hits stay in the ray's own t.
    const float base = t_enter;
    for (int a = 0; a < 3; ++a) {
        if (r.step[a] != 0) {
            r.org[a] = static_cast<float>(static_cast<double>(ray.org[a]) +
                                          static_cast<double>(ray.dir[a]) * static_cast<double>(base));
        }
    }

    // Start cell and the distance to its exit along each axis.
    int cell[3];
    float t_next[3];
    for (int a = 0; a < 3; ++a) {
        if (r.step[a] == 0) {
            float c = floorf((r.org[a] - g.origin[a]) * g.inv_cell_size);
            c = fminf(fmaxf(c, 0.0f), static_cast<float>(g.dims[a] - 1));
            cell[a] = static_cast<int>(c);
            t_next[a] = kInfinity;
        } else {
            cell[a] = cell_at(g, r, a, 0.0f);
            t_next[a] = cell_exit(g, r, a, cell[a]);
        }
    }
    const uint32_t stride[3] = {1u, static_cast<uint32_t>(g.dims[0]),
                                static_cast<uint32_t>(g.dims[0]) * static_cast<uint32_t>(g.dims[1])};
    uint32_t index = static_cast<uint32_t>(cell[0]) + stride[1] * static_cast<uint32_t>(cell[1]) +
                     stride[2] * static_cast<uint32_t>(cell[2]);
    const WatertightRay tri_ray = WatertightRay::make(ray);
    uint32_t mailbox[kGridMailboxSize];
    for (int m = 0; m < kGridMailboxSize; ++m) mailbox[m] = kInvalidId;
    int mailbox_next = 0;

    for (;;) {
        if constexpr (kCount) ++counters->cells_visited;
        const uint32_t begin = g.cell_start[index];
        const uint32_t end = g.cell_start[index + 1];

        if (begin == end && g.proximity != nullptr && g.proximity[index] > 1) {
            // Proximity jump: leave the empty cube of radius D - 1 around this cell.
            const int radius = static_cast<int>(g.proximity[index]) - 1;
            float t_jump = kInfinity;
            int jump_axis = -1;
            int jump_plane = 0;
            for (int a = 0; a < 3; ++a) {
                if (r.step[a] == 0) continue;
                const int plane = r.step[a] > 0 ? (cell[a] + radius + 1 < g.dims[a] ? cell[a] + radius + 1 : g.dims[a])
                                                : (cell[a] - radius > 0 ? cell[a] - radius : 0);
                const float t = plane_distance(g, r, a, plane);
                if (t < t_jump) {
                    t_jump = t;
                    jump_axis = a;
                    jump_plane = plane;
                }
            }
            if (jump_axis < 0 || !(base + t_jump <= grid_widen(t_limit))) return hit;
            if (jump_plane == 0 || jump_plane == g.dims[jump_axis]) return hit;  // the cube's exit face is the grid's
            for (int a = 0; a < 3; ++a) {
                if (r.step[a] == 0) continue;
                if (a == jump_axis) {
                    cell[a] = r.step[a] > 0 ? jump_plane : jump_plane - 1;
                } else {
                    const int c = cell_at(g, r, a, t_jump);
                    // Never step back (rounding); the DDA only moves forwards.
                    cell[a] = r.step[a] > 0 ? (c > cell[a] ? c : cell[a]) : (c < cell[a] ? c : cell[a]);
                }
                t_next[a] = cell_exit(g, r, a, cell[a]);
            }
            index = static_cast<uint32_t>(cell[0]) + stride[1] * static_cast<uint32_t>(cell[1]) +
                    stride[2] * static_cast<uint32_t>(cell[2]);
            continue;
        }

        for (uint32_t slot = begin; slot < end; ++slot) {
            const uint32_t prim = g.cell_prims[slot];
            // Mailbox: a triangle spanning several cells is tested once; a
            // repeated test could only give the same result again.
            bool tested = false;
            for (int m = 0; m < kGridMailboxSize; ++m) tested |= mailbox[m] == prim;
            if (tested) continue;
            mailbox[mailbox_next] = prim;
            mailbox_next = (mailbox_next + 1) & (kGridMailboxSize - 1);
            if constexpr (kCount) ++counters->prims_tested;
            TriangleHit candidate;
            if (intersect_triangle(tri_ray, g.triangles[prim], ray.tmin, t_limit, candidate)) {
                hit.t = candidate.t;
                hit.u = candidate.u;
                hit.v = candidate.v;
                hit.prim = prim;
                if constexpr (kAnyHit) return hit;
                t_limit = candidate.t;  // later triangles must beat it
            }
        }

        // Next cell: across the nearest boundary, unless it starts beyond the
        // closest hit (or the ray's end).
        const int axis = t_next[0] <= t_next[1] ? (t_next[0] <= t_next[2] ? 0 : 2) : (t_next[1] <= t_next[2] ? 1 : 2);
        if (!(base + t_next[axis] <= grid_widen(t_limit))) return hit;
        cell[axis] += r.step[axis];
        if (cell[axis] < 0 || cell[axis] >= g.dims[axis]) return hit;
        index += r.step[axis] > 0 ? stride[axis] : 0u - stride[axis];
        t_next[axis] = cell_exit(g, r, axis, cell[axis]);
    }
}

}  // namespace detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim indexes grid.triangles.
RF_HDI Hit grid_intersect(const GridView& grid, const Ray& ray) {
    return detail::grid_traverse<false, false>(grid, ray, nullptr);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
RF_HDI bool grid_occluded(const GridView& grid, const Ray& ray) {
    return detail::grid_traverse<true, false>(grid, ray, nullptr).found();
}

// Counting variants, for traversal statistics (counters are accumulated).
RF_HDI Hit grid_intersect_counted(const GridView& grid, const Ray& ray, GridTraversalCounters& counters) {
    return detail::grid_traverse<false, true>(grid, ray, &counters);
}
RF_HDI bool grid_occluded_counted(const GridView& grid, const Ray& ray, GridTraversalCounters& counters) {
    return detail::grid_traverse<true, true>(grid, ray, &counters).found();
}

}  // namespace rf
