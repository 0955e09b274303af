// Triangle/box overlap by the separating axis theorem, after Akenine-Möller,
// "Fast 3D Triangle-Box Overlap Testing", JGT 6(1), 2001 (seed 001, §2.1.2:
// the exact voxel test of the uniform-grid build).
//
// A triangle and an axis-aligned box are disjoint iff one of 13 axes
// separates their projections: the 3 box face normals (the triangle's AABB
// against the box), the triangle normal (its plane against the box), and the
// 9 cross products of a box axis with a triangle edge.
//
// Computed in double: the build inflates its cells by a small margin anyway,
// but a double test means the only slack that matters is that margin.
// Touching counts as overlap (all rejections are strict), and degenerate
// triangles behave sensibly: a zero normal or a zero edge gives a zero axis,
// which separates nothing, so a collinear triangle is tested as its segment
// and a point triangle as its point.
#pragma once

#include <cmath>

#include "rayforge/math/vec.h"

namespace rf {

struct SatVec3 {
    double x = 0, y = 0, z = 0;
    SatVec3() = default;
    constexpr SatVec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
    explicit SatVec3(Vec3f v) : x(v.x), y(v.y), z(v.z) {}
};

inline SatVec3 operator-(SatVec3 a, SatVec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline double sat_dot(SatVec3 a, SatVec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline SatVec3 sat_cross(SatVec3 a, SatVec3 b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

namespace detail {

// Plain min/max (std::fmin/fmax are library calls without -ffast-math).
inline double sat_min(double a, double b) { return a < b ? a : b; }
inline double sat_max(double a, double b) { return a > b ? a : b; }

// True when `axis` separates the triangle (v0, v1, v2; box-centred) from the
// box of half-size h centred at the origin.
inline bool sat_separates(SatVec3 axis, SatVec3 v0, SatVec3 v1, SatVec3 v2, SatVec3 h) {
    const double p0 = sat_dot(axis, v0), p1 = sat_dot(axis, v1), p2 = sat_dot(axis, v2);
    const double r = h.x * std::fabs(axis.x) + h.y * std::fabs(axis.y) + h.z * std::fabs(axis.z);
    const double lo = sat_min(p0, sat_min(p1, p2));
    const double hi = sat_max(p0, sat_max(p1, p2));
    return lo > r || hi < -r;
}

}  // namespace detail

// True when triangle (a, b, c) and the box centre ± half overlap (or touch).
inline bool triangle_box_overlap(SatVec3 center, SatVec3 half, SatVec3 a, SatVec3 b, SatVec3 c) {
    // Box-local coordinates.
    const SatVec3 v0 = a - center, v1 = b - center, v2 = c - center;

    // 3 box face normals: the triangle's AABB against the box (cheapest, most selective first).
    using detail::sat_max;
    using detail::sat_min;
    if (sat_min(v0.x, sat_min(v1.x, v2.x)) > half.x || sat_max(v0.x, sat_max(v1.x, v2.x)) < -half.x) return false;
    if (sat_min(v0.y, sat_min(v1.y, v2.y)) > half.y || sat_max(v0.y, sat_max(v1.y, v2.y)) < -half.y) return false;
    if (sat_min(v0.z, sat_min(v1.z, v2.z)) > half.z || sat_max(v0.z, sat_max(v1.z, v2.z)) < -half.z) return false;

    const SatVec3 f0 = v1 - v0, f1 = v2 - v1, f2 = v0 - v2;

    // The triangle's plane: the box projects onto n as [-r, r] around the
    // centre; the plane sits at n . v0.
    const SatVec3 n = sat_cross(f0, f1);
    const double plane = sat_dot(n, v0);
    const double r = half.x * std::fabs(n.x) + half.y * std::fabs(n.y) + half.z * std::fabs(n.z);
    if (plane > r || plane < -r) return false;

    // 9 edge axes e_i x f_j.
    for (const SatVec3 f : {f0, f1, f2}) {
        if (detail::sat_separates({0.0, -f.z, f.y}, v0, v1, v2, half)) return false;  // e_x x f
        if (detail::sat_separates({f.z, 0.0, -f.x}, v0, v1, v2, half)) return false;  // e_y x f
        if (detail::sat_separates({-f.y, f.x, 0.0}, v0, v1, v2, half)) return false;  // e_z x f
    }
    return true;
}

}  // namespace rf
