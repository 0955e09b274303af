// The closest point of a triangle to a point, and the BVH point query over
// a QueryView (mesh_queries.cpp runs it per query).
//
// Per triangle: Ericson, "Real-Time Collision Detection" (2005), 5.1.5:
// the point's Voronoi region of the triangle (three vertex regions, three
// edge regions, the face) is found from six dot products, and the closest
// point is the vertex, the projection on the edge, or the projection on
// the plane from the barycentrics (va, vb, vc) / (va + vb + vc), whose sum
// is |ab x ac|^2. A zero-area triangle (flagged when the slots are made)
// is the union of its three edges: the nearest of the three segment
// projections (5.1.2, a zero-length segment being its point).
//
// Traversal: optionally seeded with a triangle's distance (a nearby
// query's answer), then depth-first, the nearer child (smaller squared box distance)
// first, the other pushed with its distance; a node is entered only while
// its squared box distance is <= the best squared distance so far, so a
// triangle at the same distance as the best is still tested and ties go to
// the smallest prim whatever order the nodes are visited in. The box of a
// triangle's node never lies farther (in float) than the triangle's
// vertices, which makes ties at shared vertices exact.
#pragma once

#include <cstdint>

#include "accel/query/query_mesh.h"
#include "core/assert.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/math/ray.h"

namespace rf::query {

struct TrianglePoint {
    Vec3f point;
    float u = 0.0f, v = 0.0f;  // barycentrics of v1 and v2
};

// Closest point of segment a + s (b - a), s in [0, 1], to p (Ericson 5.1.2); s is returned.
RF_HDI float closest_segment_parameter(Vec3f p, Vec3f a, Vec3f b) {
    const Vec3f ab = b - a;
    const float len2 = dot(ab, ab);
    if (!(len2 > 0.0f)) return 0.0f;
    const float s = dot(p - a, ab) / len2;
    return s < 0.0f ? 0.0f : (s > 1.0f ? 1.0f : s);
}

// Closest point of a zero-area triangle: the nearest of its three edges (the first on ties).
RF_HDI TrianglePoint closest_point_on_flat_triangle(Vec3f p, const Triangle& t) {
    const float s0 = closest_segment_parameter(p, t.v0, t.v1);  // v0 -> v1
    const float s1 = closest_segment_parameter(p, t.v1, t.v2);  // v1 -> v2
    const float s2 = closest_segment_parameter(p, t.v2, t.v0);  // v2 -> v0
    const Vec3f q0 = t.v0 + (t.v1 - t.v0) * s0;
    const Vec3f q1 = t.v1 + (t.v2 - t.v1) * s1;
    const Vec3f q2 = t.v2 + (t.v0 - t.v2) * s2;
    const float d0 = length_squared(q0 - p), d1 = length_squared(q1 - p), d2 = length_squared(q2 - p);
    if (d0 <= d1 && d0 <= d2) return {q0, s0, 0.0f};
    if (d1 <= d2) return {q1, 1.0f - s1, s1};
    return {q2, 0.0f, 1.0f - s2};
}

// num / den for 0 <= num <= den, and 0 when den is 0 (an edge so short
// against the query's distance that both its dot products rounded to 0).
RF_HDI float safe_ratio(float num, float den) { return den > 0.0f ? num / den : 0.0f; }

// Ericson 5.1.5 for a triangle of non-zero area.
RF_HDI TrianglePoint closest_point_on_triangle(Vec3f p, const Triangle& t) {
    const Vec3f ab = t.v1 - t.v0;
    const Vec3f ac = t.v2 - t.v0;
    const Vec3f ap = p - t.v0;
    const float d1 = dot(ab, ap);
    const float d2 = dot(ac, ap);
    if (d1 <= 0.0f && d2 <= 0.0f) return {t.v0, 0.0f, 0.0f};  // vertex region of v0

    const Vec3f bp = p - t.v1;
    const float d3 = dot(ab, bp);
    const float d4 = dot(ac, bp);
    if (d3 >= 0.0f && d4 <= d3) return {t.v1, 1.0f, 0.0f};  // vertex region of v1

    const float vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f) {  // edge region of v0 v1
        const float s = safe_ratio(d1, d1 - d3);
        return {t.v0 + ab * s, s, 0.0f};
    }

    const Vec3f cp = p - t.v2;
    const float d5 = dot(ab, cp);
    const float d6 = dot(ac, cp);
    if (d6 >= 0.0f && d5 <= d6) return {t.v2, 0.0f, 1.0f};  // vertex region of v2

    const float vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f) {  // edge region of v0 v2
        const float s = safe_ratio(d2, d2 - d6);
        return {t.v0 + ac * s, 0.0f, s};
    }

    const float va = d3 * d6 - d5 * d4;
    const float e43 = d4 - d3, e56 = d5 - d6;
    if (va <= 0.0f && e43 >= 0.0f && e56 >= 0.0f) {  // edge region of v1 v2
        const float s = safe_ratio(e43, e43 + e56);
        return {t.v1 + (t.v2 - t.v1) * s, 1.0f - s, s};
    }

    // Face region; va + vb + vc = |ab x ac|^2 > 0 in exact arithmetic, but a
    // sliver may round it to zero: its edges then give the answer.
    const float sum = va + vb + vc;
    if (!(sum > 0.0f)) return closest_point_on_flat_triangle(p, t);
    const float inv = 1.0f / sum;
    const float v = vb * inv, w = vc * inv;
    return {t.v0 + ab * v + ac * w, v, w};
}

RF_HDI TrianglePoint closest_point_on_slot(Vec3f p, const SlotTriangle& s) {
    return s.zero_area() ? closest_point_on_flat_triangle(p, s.tri) : closest_point_on_triangle(p, s.tri);
}

// Squared distance from p to the box (0 inside). Comparisons, not fmaxf:
// GCC calls libm's fmaxf (NaN rules) instead of one max instruction, and
// p and the box are finite here.
RF_HDI float box_distance_squared(Vec3f p, const Box3f& b) {
    auto gap = [](float lo, float x, float hi) {
        const float below = lo - x, above = x - hi;
        const float d = below > above ? below : above;
        return d > 0.0f ? d : 0.0f;
    };
    const float dx = gap(b.lo.x, p.x, b.hi.x), dy = gap(b.lo.y, p.y, b.hi.y), dz = gap(b.lo.z, p.z, b.hi.z);
    return dx * dx + dy * dy + dz * dz;
}

struct PointQueryResult {
    TrianglePoint point;
    float distance_squared = kInfinity;
    uint32_t prim = kInvalidId;
    uint32_t slot = kInvalidId;
};

RF_HDI void consider_slot(const QueryView& view, Vec3f p, uint32_t s, PointQueryResult& best) {
    const SlotTriangle& slot = view.slots[s];
    const TrianglePoint c = closest_point_on_slot(p, slot);
    const float d = length_squared(c.point - p);
    const uint32_t prim = slot.prim();
    if (d < best.distance_squared || (d == best.distance_squared && prim < best.prim)) {
        best.point = c;
        best.distance_squared = d;
        best.prim = prim;
        best.slot = s;
    }
}

// The closest point of the view's triangles to p (p finite; prim ==
// kInvalidId for an empty view). seed_slot (a slot, or kInvalidId): a
// triangle whose distance starts as the best, typically the answer of a
// nearby query; it only prunes more, the answer (the smallest distance,
// then the smallest prim) stays the same.
RF_HDI PointQueryResult closest_point_query(const QueryView& view, Vec3f p, uint32_t seed_slot = kInvalidId) {
    PointQueryResult best;
    if (view.node_count == 0) return best;
    if (seed_slot != kInvalidId) consider_slot(view, p, seed_slot, best);
    struct Entry {
        uint32_t node;
        float distance_squared;
    };
    Entry stack[kQueryStackSize];
    int size = 0;
    uint32_t current = 0;
    for (;;) {
        const BvhNode& node = view.nodes[current];
        if (!node.is_leaf()) {
            const uint32_t left = node.first;
            const float dl = box_distance_squared(p, view.nodes[left].bounds);
            const float dr = box_distance_squared(p, view.nodes[left + 1].bounds);
            const bool left_first = dl <= dr;
            const float near_d = left_first ? dl : dr, far_d = left_first ? dr : dl;
            if (near_d <= best.distance_squared) {
                if (far_d <= best.distance_squared) {
                    RF_ASSERT(size < kQueryStackSize, "a BVH deeper than kBvhMaxDepth");
                    stack[size++] = {left_first ? left + 1 : left, far_d};
                }
                current = left_first ? left : left + 1;
                continue;
            }
        } else {
            const uint32_t end = node.first + node.count;
            for (uint32_t s = node.first; s < end; ++s) consider_slot(view, p, s, best);
        }
        for (;;) {
            if (size == 0) return best;
            const Entry e = stack[--size];
            if (e.distance_squared <= best.distance_squared) {
                current = e.node;
                break;
            }
        }
    }
}

}  // namespace rf::query
