// "Perfect splits" for the kd-tree build (Wald and Havran 2006, sec. 4.3;
// Havran 2000): a triangle is clipped to a cell with Sutherland-Hodgman
// (one pass per box face) and the clipped polygon's bounds replace the
// triangle's, so splits and classification see only the part inside the cell.
#pragma once

#include <cmath>

#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

namespace clip_detail {

struct Point3d {
    double c[3];
};

// Keeps the part of `in` on the inner side of the plane x[axis] = plane
// (keep_above: x >= plane, else x <= plane); returns the new vertex count.
// A triangle gains at most one vertex per plane: 3 + 6 = 9 at most.
inline int clip_against(const Point3d* in, int count, Point3d* out, int axis, double plane, bool keep_above) {
    int written = 0;
    for (int i = 0; i < count; ++i) {
        const Point3d& a = in[i];
        const Point3d& b = in[(i + 1) % count];
        const bool a_in = keep_above ? a.c[axis] >= plane : a.c[axis] <= plane;
        const bool b_in = keep_above ? b.c[axis] >= plane : b.c[axis] <= plane;
        if (a_in) out[written++] = a;
        if (a_in != b_in) {
            // The edge crosses the plane: add the crossing, on the plane exactly.
            const double t = (plane - a.c[axis]) / (b.c[axis] - a.c[axis]);
            Point3d p;
            for (int k = 0; k < 3; ++k) p.c[k] = a.c[k] + t * (b.c[k] - a.c[k]);
            p.c[axis] = plane;
            out[written++] = p;
        }
    }
    return written;
}

// Largest float <= x and smallest float >= x: bounds round outwards.
inline float float_down(double x) {
    float f = static_cast<float>(x);
    if (static_cast<double>(f) > x) f = std::nextafter(f, -INFINITY);
    return f;
}
inline float float_up(double x) {
    float f = static_cast<float>(x);
    if (static_cast<double>(f) < x) f = std::nextafter(f, INFINITY);
    return f;
}

}  // namespace clip_detail

// Bounds of the part of `tri` inside the closed box `cell`, clamped to the
// cell; false when nothing of the triangle is in the cell. Computed in double
// so that a triangle overlapping a cell is not lost to rounding.
inline bool clip_triangle_bounds(const Triangle& tri, const Box3f& cell, Box3f& bounds) {
    using clip_detail::Point3d;
    Point3d buffers[2][10];
    const Vec3f v[3] = {tri.v0, tri.v1, tri.v2};
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) buffers[0][i].c[k] = v[i][k];
    int count = 3;
    int current = 0;
    for (int axis = 0; axis < 3; ++axis) {
        // Only planes that cut the polygon need a pass (usually one or two).
        double lo = INFINITY, hi = -INFINITY;
        for (int i = 0; i < count; ++i) {
            lo = std::fmin(lo, buffers[current][i].c[axis]);
            hi = std::fmax(hi, buffers[current][i].c[axis]);
        }
        if (hi < cell.lo[axis] || lo > cell.hi[axis]) return false;
        if (lo < cell.lo[axis]) {
            count = clip_detail::clip_against(buffers[current], count, buffers[1 - current], axis, cell.lo[axis], true);
            current = 1 - current;
            if (count == 0) return false;
        }
        if (hi > cell.hi[axis]) {
            count = clip_detail::clip_against(buffers[current], count, buffers[1 - current], axis, cell.hi[axis], false);
            current = 1 - current;
            if (count == 0) return false;
        }
    }
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < count; ++i) {
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::fmin(lo[k], buffers[current][i].c[k]);
            hi[k] = std::fmax(hi[k], buffers[current][i].c[k]);
        }
    }
    for (int k = 0; k < 3; ++k) {
        bounds.lo[k] = std::fmax(clip_detail::float_down(lo[k]), cell.lo[k]);
        bounds.hi[k] = std::fmin(clip_detail::float_up(hi[k]), cell.hi[k]);
        if (bounds.lo[k] > bounds.hi[k]) return false;
    }
    return true;
}

}  // namespace rf
