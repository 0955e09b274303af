// Every hit of a ray over a QueryView, and the rule that merges the hits of
// one crossing of a shared edge or vertex (mesh_queries.cpp: list and count).
//
// The traversal is the closest-hit loop of trace/bvh_traversal.h without
// the shrinking interval: every node whose box the ray overlaps within
// [tmin, tmax] (Ize 2013's robust slab test, the same SlabRay) is opened and
// every triangle tested with the watertight test (Woop et al. 2013), so a
// ray crossing a closed mesh at an edge or a vertex hits at least one of
// the triangles there, and possibly several at (almost) the same t.
#pragma once

#include <cstdint>
#include <vector>

#include "accel/query/query_mesh.h"
#include "core/assert.h"
#include "rayforge/core/host_device.h"
#include "trace/bvh_traversal.h"
#include "trace/triangle_intersect.h"

namespace rf::query {

struct SlotHit {
    float t, u, v;
    uint32_t slot;  // into QueryView::slots
};

// A ray that can hit anything: finite origin and direction, a non-zero
// direction, tmin and tmax not NaN.
RF_HDI bool ray_can_hit(const Ray& ray) {
    return is_finite(ray.org) && is_finite(ray.dir) && !(ray.dir.x == 0.0f && ray.dir.y == 0.0f && ray.dir.z == 0.0f) &&
           ray.tmin == ray.tmin && ray.tmax == ray.tmax;
}

// visit(SlotHit) for every leaf slot whose triangle the ray hits with t in
// [ray.tmin, ray.tmax], in traversal order (ray_can_hit(ray) assumed).
template <class Visit>
RF_HDI void for_each_hit(const QueryView& view, const Ray& ray, Visit&& visit) {
    if (view.node_count == 0) return;
    // The robust slab test widens the far distance of t >= 0 only, so a ray
    // with tmin < 0 tests its part behind the origin as the mirrored ray
    // (org, -dir) over [-min(tmax, 0), -tmin]: exactly the negated slab
    // distances. Triangles are always tested with the ray as given.
    const bool ahead = ray.tmax >= 0.0f, behind = ray.tmin < 0.0f;
    const detail::SlabRay forward = detail::SlabRay::make(ray);
    const detail::SlabRay backward = detail::SlabRay::make(Ray{ray.org, 0.0f, -ray.dir, kInfinity});
    const float forward_min = ahead && behind ? 0.0f : ray.tmin;
    const float backward_min = ahead ? 0.0f : -ray.tmax;
    auto overlaps = [&](const Box3f& box) {
        float entry;
        return (ahead && detail::slab_test(forward, box, forward_min, ray.tmax, entry)) ||
               (behind && detail::slab_test(backward, box, backward_min, -ray.tmin, entry));
    };
    if (!overlaps(view.nodes[0].bounds)) return;
    const WatertightRay tri_ray = WatertightRay::make(ray);
    uint32_t stack[kQueryStackSize];
    int size = 0;
    stack[size++] = 0;
    while (size > 0) {
        const BvhNode& node = view.nodes[stack[--size]];
        if (node.is_leaf()) {
            for (uint32_t s = node.first; s < node.first + node.count; ++s) {
                const SlotTriangle& slot = view.slots[s];
                TriangleHit hit;
                if (!slot.zero_area() && intersect_triangle(tri_ray, slot.tri, ray.tmin, ray.tmax, hit)) {
                    visit(SlotHit{hit.t, hit.u, hit.v, s});
                }
            }
            continue;
        }
        RF_ASSERT(size + 2 <= kQueryStackSize, "a BVH deeper than kBvhMaxDepth");
        const uint32_t left = node.first;
        if (overlaps(view.nodes[left + 1].bounds)) stack[size++] = left + 1;
        if (overlaps(view.nodes[left].bounds)) stack[size++] = left;
    }
}

// Sorts one ray's hits by (t, prim) and removes, in place, every hit for
// which another hit with a smaller prim (or the same prim: a triangle
// referenced from two leaves) lies within |dt| <= 1e-6 max(1, |t|, |t'|)
// on a triangle sharing a vertex (bit-equal position) with its own; the
// kept hits stay sorted. The rule depends on the set of hits only, not on
// the order they were found in.
void merge_shared_hits(std::vector<SlotHit>& hits, const SlotTriangle* slots);

}  // namespace rf::query
