// Watertight ray/triangle intersection after Woop, Benthin and Wald,
// "Watertight Ray/Triangle Intersection", JCGT 2(1), 2013.
//
// The ray is turned into a unit ray along +z by a permutation (kx, ky, kz) and
// a shear (Sx, Sy, Sz) computed once per ray. Each triangle's vertices are
// translated, permuted and sheared the same way, so a vertex shared by two
// triangles maps to bit-identical 2D points and the three 2D edge functions
// U, V, W decide inside/outside consistently along shared edges: a ray can
// slip through no crack between triangles of a closed mesh.
//
// Two details keep that promise on real compilers:
//  - with FMA hardware the compiler may contract a*b - c*d into
//    fma(a, b, -c*d), which is not antisymmetric in its operands and would
//    reopen the cracks. The edge functions therefore use Kahan's
//    difference of products, whose sign is always the exact sign.
//  - when an edge function is exactly 0 the paper recomputes U, V, W in
//    double, where the products of floats are exact.
#pragma once

#include <cmath>

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Per-ray constants of the watertight test.
struct WatertightRay {
    Vec3f org;
    int kx = 0, ky = 1, kz = 2;   // permutation: kz is the dominant direction axis
    float sx = 0, sy = 0, sz = 1; // shear taking dir to (0, 0, 1)

    RF_HDI static WatertightRay make(const Ray& ray) {
        WatertightRay w;
        w.org = ray.org;
        const Vec3f a = abs(ray.dir);
        w.kz = (a.x >= a.y && a.x >= a.z) ? 0 : (a.y >= a.z ? 1 : 2);
        w.kx = w.kz == 2 ? 0 : w.kz + 1;
        w.ky = w.kx == 2 ? 0 : w.kx + 1;
        // Keep the winding of the projected triangle independent of the ray's sign.
        if (ray.dir[w.kz] < 0.0f) {
            const int swap = w.kx; w.kx = w.ky; w.ky = swap;
        }
        w.sx = ray.dir[w.kx] / ray.dir[w.kz];
        w.sy = ray.dir[w.ky] / ray.dir[w.kz];
        w.sz = 1.0f / ray.dir[w.kz];
        return w;
    }
};

namespace detail {

// a - s * b, evaluated identically for every vertex (an explicit fma where the
// hardware has one, so that contraction cannot treat vertices differently).
RF_HDI float shear_coordinate(float a, float s, float b) {
#if defined(__CUDA_ARCH__) || defined(__FMA__)
    return fmaf(-s, b, a);
#else
    return a - s * b;
#endif
}

// a * b - c * d with the exact sign (and exactly 0 only when a*b == c*d).
RF_HDI float difference_of_products(float a, float b, float c, float d) {
#if defined(__CUDA_ARCH__) || defined(__FMA__)
    const float cd = c * d;
    const float error = fmaf(-c, d, cd);  // cd - c*d, exact
    const float dop = fmaf(a, b, -cd);
    return dop + error;
#else
    // Without FMA instructions nothing is contracted: the difference is
    // antisymmetric as written and exact zeros go to the double fallback.
    return a * b - c * d;
#endif
}

// a*b + c*d + e*f, evaluated the same way wherever it is inlined (so that a
// triangle's t never depends on which traversal called the test).
RF_HDI float sum_of_products(float a, float b, float c, float d, float e, float f) {
#if defined(__CUDA_ARCH__) || defined(__FMA__)
    return fmaf(a, b, fmaf(c, d, e * f));
#else
    return a * b + c * d + e * f;
#endif
}

}  // namespace detail

// Result of one ray/triangle test.
struct TriangleHit {
    float t, u, v;  // u, v: barycentrics of v1 and v2 (as in rf::Hit)
};

// Tests one triangle; true and `hit` filled when tmin <= t <= tmax. Both
// facings hit; degenerate (zero-area) triangles never hit.
RF_HDI bool intersect_triangle(const WatertightRay& ray, const Triangle& tri, float tmin, float tmax,
                               TriangleHit& hit) {
    const Vec3f a = tri.v0 - ray.org;
    const Vec3f b = tri.v1 - ray.org;
    const Vec3f c = tri.v2 - ray.org;
    const float ax = detail::shear_coordinate(a[ray.kx], ray.sx, a[ray.kz]);
    const float ay = detail::shear_coordinate(a[ray.ky], ray.sy, a[ray.kz]);
    const float bx = detail::shear_coordinate(b[ray.kx], ray.sx, b[ray.kz]);
    const float by = detail::shear_coordinate(b[ray.ky], ray.sy, b[ray.kz]);
    const float cx = detail::shear_coordinate(c[ray.kx], ray.sx, c[ray.kz]);
    const float cy = detail::shear_coordinate(c[ray.ky], ray.sy, c[ray.kz]);

    // Scaled barycentrics: U weighs v0, V weighs v1, W weighs v2.
    float u = detail::difference_of_products(cx, by, cy, bx);
    float v = detail::difference_of_products(ax, cy, ay, cx);
    float w = detail::difference_of_products(bx, ay, by, ax);
    if (u == 0.0f || v == 0.0f || w == 0.0f) {
        // On an edge (or a vertex) in float: decide with exact products.
        u = static_cast<float>(static_cast<double>(cx) * by - static_cast<double>(cy) * bx);
        v = static_cast<float>(static_cast<double>(ax) * cy - static_cast<double>(ay) * cx);
        w = static_cast<float>(static_cast<double>(bx) * ay - static_cast<double>(by) * ax);
    }
    // Inside when the three edge functions agree in sign (either facing).
    if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
    const float det = u + v + w;
    if (det == 0.0f) return false;  // degenerate, or the ray lies in the triangle's plane

    const float az = ray.sz * a[ray.kz];
    const float bz = ray.sz * b[ray.kz];
    const float cz = ray.sz * c[ray.kz];
    const float scaled_t = detail::sum_of_products(u, az, v, bz, w, cz);
    const float inv_det = 1.0f / det;
    const float t = scaled_t * inv_det;
    if (!(t >= tmin && t <= tmax)) return false;  // also rejects NaN
    // A zero-area triangle (collinear vertices) can survive the test above,
    // because the shear rounds its vertices off their common line; it has no
    // normal to shade with, so it never counts as hit. Checked only for
    // accepted candidates, so it costs nothing on the many misses.
    const Vec3f normal = cross(tri.v1 - tri.v0, tri.v2 - tri.v0);
    if (normal.x == 0.0f && normal.y == 0.0f && normal.z == 0.0f) return false;
    hit.t = t;
    hit.u = v * inv_det;
    hit.v = w * inv_det;
    return true;
}

}  // namespace rf
