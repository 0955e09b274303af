// Closest-hit and any-hit traversal of the canonical binary BVH (rf::Bvh),
// written once for the host and the CUDA backend: the structure is passed as
// raw pointers so device copies work the same way.
//
// Box tests follow Ize, "Robust BVH Ray Traversal", JCGT 2(2), 2013: slab
// distances are computed as (plane - origin) * (1 / dir) and the far distance
// is enlarged by 1 + 2 * gamma(3) so that rounding never culls a box the ray
// really enters (which would break the watertight triangle test's promise).
// The ray's own tmax gets the same slack: a triangle lying in a box face has
// the face's distance up to rounding, and must not be culled by its own box
// once a hit at (almost) the same distance shrank tmax.
// Zero direction components give infinite reciprocals; the min/max below are
// written so that the resulting NaN (0 * inf, for an origin exactly on a slab
// plane) leaves the interval unchanged instead of poisoning it.
#pragma once

#include <cstdint>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "core/assert.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/triangle_intersect.h"

namespace rf {

// A BVH as the traversal sees it; node_count == 0 is the empty BVH (every ray misses).
struct BvhView {
    const BvhNode* nodes = nullptr;
    const uint32_t* prim_indices = nullptr;
    const Triangle* triangles = nullptr;
    uint32_t node_count = 0;
};

// Work done by one traversal (filled by the counting variants).
struct TraversalCounters {
    uint32_t nodes_visited = 0;  // box tests
    uint32_t prims_tested = 0;   // triangle tests
};

namespace detail {

// Max/min that ignore a NaN first argument (keeping the running bound).
RF_HDI float max_keep(float x, float bound) { return x > bound ? x : bound; }
RF_HDI float min_keep(float x, float bound) { return x < bound ? x : bound; }

// Per-ray constants of the slab test.
struct SlabRay {
    Vec3f org;
    Vec3f inv_dir;
    bool neg_x, neg_y, neg_z;  // octant: which box side is entered first

    RF_HDI static SlabRay make(const Ray& ray) {
        SlabRay s;
        s.org = ray.org;
        s.inv_dir = Vec3f(1.0f / ray.dir.x, 1.0f / ray.dir.y, 1.0f / ray.dir.z);
        s.neg_x = s.inv_dir.x < 0.0f;
        s.neg_y = s.inv_dir.y < 0.0f;
        s.neg_z = s.inv_dir.z < 0.0f;
        return s;
    }
};

// 1 + 2 * gamma(3), gamma(n) = n * u / (1 - n * u), u = 2^-24 (Ize 2013, pbrt).
inline constexpr float kSlabFarScale = 1.0f + 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);

// True when the ray overlaps `box` within [tmin, tmax]; `entry` is where it enters.
RF_HDI bool slab_test(const SlabRay& r, const Box3f& box, float tmin, float tmax, float& entry) {
    const float tx0 = ((r.neg_x ? box.hi.x : box.lo.x) - r.org.x) * r.inv_dir.x;
    const float tx1 = ((r.neg_x ? box.lo.x : box.hi.x) - r.org.x) * r.inv_dir.x;
    const float ty0 = ((r.neg_y ? box.hi.y : box.lo.y) - r.org.y) * r.inv_dir.y;
    const float ty1 = ((r.neg_y ? box.lo.y : box.hi.y) - r.org.y) * r.inv_dir.y;
    const float tz0 = ((r.neg_z ? box.hi.z : box.lo.z) - r.org.z) * r.inv_dir.z;
    const float tz1 = ((r.neg_z ? box.lo.z : box.hi.z) - r.org.z) * r.inv_dir.z;
    const float t_near = max_keep(tz0, max_keep(ty0, max_keep(tx0, tmin)));
    const float slab_far = min_keep(tz1, min_keep(ty1, min_keep(tx1, kInfinity)));
    const float t_far = min_keep(slab_far * kSlabFarScale, tmax * kSlabFarScale);
    entry = t_near;
    return t_near <= t_far;
}

struct StackEntry {
    uint32_t node;
    float entry;  // distance at which the ray enters the node's box
};

// Shared loop: closest hit (kAnyHit = false) or first hit (kAnyHit = true).
template <bool kAnyHit, bool kCount>
RF_HDI Hit traverse(const BvhView& bvh, const Ray& ray, TraversalCounters* counters) {
    Hit hit;
    if (bvh.node_count == 0) return hit;
    const SlabRay slab = SlabRay::make(ray);
    const WatertightRay tri_ray = WatertightRay::make(ray);
    const float tmin = ray.tmin;
    float tmax = ray.tmax;

    float entry;
    if constexpr (kCount) ++counters->nodes_visited;
    if (!slab_test(slab, bvh.nodes[0].bounds, tmin, tmax, entry)) return hit;

    StackEntry stack[kBvhMaxDepth];  // one far child per inner node on the path
    int stack_size = 0;
    uint32_t current = 0;
    for (;;) {
        const BvhNode& node = bvh.nodes[current];
        if (!node.is_leaf()) {
            const uint32_t left = node.first;
            RF_ASSERT(left + 1 < bvh.node_count, "an inner node's children lie beyond the node array");
            float entry_left, entry_right;
            const bool hit_left = slab_test(slab, bvh.nodes[left].bounds, tmin, tmax, entry_left);
            const bool hit_right = slab_test(slab, bvh.nodes[left + 1].bounds, tmin, tmax, entry_right);
            if constexpr (kCount) counters->nodes_visited += 2;
            if (hit_left && hit_right) {
                // Visit the nearer child first; the other waits on the stack.
                const bool left_first = entry_left <= entry_right;
                current = left_first ? left : left + 1;
                RF_ASSERT(stack_size < kBvhMaxDepth, "a BVH deeper than kBvhMaxDepth");
                stack[stack_size++] = left_first ? StackEntry{left + 1, entry_right} : StackEntry{left, entry_left};
                continue;
            }
            if (hit_left || hit_right) {
                current = hit_left ? left : left + 1;
                continue;
            }
        } else {
            const uint32_t end = node.first + node.count;
            for (uint32_t slot = node.first; slot < end; ++slot) {
                const uint32_t prim = bvh.prim_indices[slot];
                if constexpr (kCount) ++counters->prims_tested;
                TriangleHit candidate;
                if (intersect_triangle(tri_ray, bvh.triangles[prim], tmin, tmax, candidate)) {
                    hit.t = candidate.t;
                    hit.u = candidate.u;
                    hit.v = candidate.v;
                    hit.prim = prim;
                    if constexpr (kAnyHit) return hit;
                    tmax = candidate.t;  // later boxes and triangles must beat it
                }
            }
        }
        // Pop the next node the ray still reaches within the shrunken interval.
        for (;;) {
            if (stack_size == 0) return hit;
            const StackEntry next = stack[--stack_size];
            if (next.entry <= tmax * kSlabFarScale) {
                current = next.node;
                break;
            }
        }
    }
}

}  // namespace detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim indexes bvh.triangles.
RF_HDI Hit bvh_intersect(const BvhView& bvh, const Ray& ray) {
    return detail::traverse<false, false>(bvh, ray, nullptr);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
RF_HDI bool bvh_occluded(const BvhView& bvh, const Ray& ray) {
    return detail::traverse<true, false>(bvh, ray, nullptr).found();
}

// Counting variants, for traversal statistics (counters are accumulated).
RF_HDI Hit bvh_intersect_counted(const BvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    return detail::traverse<false, true>(bvh, ray, &counters);
}
RF_HDI bool bvh_occluded_counted(const BvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    return detail::traverse<true, true>(bvh, ray, &counters).found();
}

}  // namespace rf
