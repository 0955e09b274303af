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

#include <cmath>
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
    // Node fetches, whatever a node's width, so that layouts with different
    // box counts per node compare: the binary BVH one per inner node entered
    // (its two children's adjacent records) and one for the root's box, a
    // node pair (64 bytes) or a CWBVH node (80 bytes) one each.
    uint32_t node_fetches = 0;
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
// 1 - 2^-21 = 1 - 8u, exact: the scale of a negative far distance.
inline constexpr float kSlabFarScaleNegative = 1.0f - 0x1p-21f;

// A far distance widened by at least 2 gamma(3) of its magnitude, for either
// sign (Ize's t * kSlabFarScale narrows a negative t, which only rays with
// tmin < 0 meet). Positive t: exactly t * kSlabFarScale, as before. Negative
// t: fl(t (1 - 8u)) >= t (1 - 8u)(1 + u) = t + |t| (7u + 8u^2), and
// 7u + 8u^2 > 2 gamma(3) = 6u / (1 - 3u). Monotone in t, so it commutes with
// min; NaN stays NaN, +-inf stay.
RF_HDI float widen_far(float t) { return t * (t >= 0.0f ? kSlabFarScale : kSlabFarScaleNegative); }

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
    const float t_far = widen_far(min_keep(slab_far, tmax));  // widen_far is monotone: = min of the widened
    entry = t_near;
    return t_near <= t_far;
}

// The slab test in the FMA min/max form of Aila and Laine's kernels (2009,
// and the 2012 addendum's): per ray idir = 1/dir and ood = org * idir, per
// plane t = fma(p, idir, -ood), one rounding instead of a subtraction and a
// product; near and far by min/max, so no octant selects. Kept conservative
// (never culls a box the exact ray enters within [tmin, tmax]) by the Ize far
// scale and per-axis pads. With u = 2^-24, gamma(n) = n u / (1 - n u), the
// exact t* = (p - org) / dir and idir = (1/dir)(1 + d1):
//   fma(p, idir, -o) = ((p - org) idir - (o - org idir))(1 + d3),
// so t = t* (1 + d1)(1 + d3) (within gamma(2) of t*, relatively) as soon as
// o - org idir has the right sign: the absolute error of the FMA form comes
// from ood's rounding, |ood - org idir| <= u |ood| / (1 - u). Each axis
// therefore gets two offsets, moved apart by pad_a = 2^-22 |ood_a| = 4u |ood_a|
// (more than that error plus the offsets' own rounding, u |ood_a + pad_a|):
// the near plane's t (lo for idir > 0, hi for idir < 0) uses ood + pad_a and
// can only come out lower, the far plane's ood - pad_a and only higher:
//   near <= N* + gamma(2) |N*|,  far >= F* - gamma(2) |F*|
// for every axis, and through the min/max (x +- gamma(2)|x| are increasing)
// for the clipped t_near, t_far of the box and [tmin, tmax]. When the ray
// enters (N* <= F*):
//  - F* >= 0: t_near <= F*(1 + gamma(2)) <= t_far (1 + gamma(2)) / (1 - gamma(2))
//    = t_far / (1 - 4u) <= fl(t_far s) with Ize's s = 1 + 2 gamma(3);
//  - F* < 0 (only with tmin < 0; |F*| <= T = -tmin): t_near - t_far s is at
//    most about 11u T, covered by pad = 2^-20 T = 16u T.
// Hence: enter iff t_near <= fma(t_far, s, pad), pad = 2^-20 max(0, -tmin), at
// least FLT_MIN for the absolute rounding of results in the subnormal range.
// The offsets add one register per axis, not an instruction per box. Assumes
// no t overflows (|t| < 2^127).
// The form needs idir and the offsets finite: a zero (or subnormal) direction
// component gives idir = inf and then inf - inf = NaN planes, which min/max
// cannot order. FmaSlabRay::make says so (usable = false); such rays take
// slab_test above instead (trace/aila_laine_fma_traversal.h does).
inline constexpr float kFmaSlabAxisPad = 0x1p-22f;
inline constexpr float kFmaSlabTminPad = 0x1p-20f;
inline constexpr float kFmaSlabPadFloor = 0x1p-126f;  // FLT_MIN

struct FmaSlabRay {
    Vec3f idir;
    Vec3f ood_lo;  // org * idir, offset for the box's lo planes
    Vec3f ood_hi;  // and for its hi planes
    float pad = 0.0f;
    bool usable = false;  // everything above finite

    RF_HDI static FmaSlabRay make(const Ray& ray) {
        FmaSlabRay r;
        r.idir = Vec3f(1.0f / ray.dir.x, 1.0f / ray.dir.y, 1.0f / ray.dir.z);
        bool finite = fabsf(r.idir.x) <= kInfinity && fabsf(r.idir.y) <= kInfinity && fabsf(r.idir.z) <= kInfinity;
        for (int a = 0; a < 3; ++a) {
            const float ood = ray.org[a] * r.idir[a];
            // +pad moves a plane's t down: the lo plane's when it is the near one (idir > 0).
            const float pad = r.idir[a] > 0.0f ? kFmaSlabAxisPad * fabsf(ood) : -kFmaSlabAxisPad * fabsf(ood);
            r.ood_lo[a] = ood + pad;
            r.ood_hi[a] = ood - pad;
            finite = finite && fabsf(r.ood_lo[a]) <= kInfinity && fabsf(r.ood_hi[a]) <= kInfinity;
        }
        r.pad = fmaxf(kFmaSlabTminPad * fmaxf(-ray.tmin, 0.0f), kFmaSlabPadFloor);
        r.usable = finite && r.pad <= kInfinity;
        return r;
    }
};

// True when the ray overlaps `box` within [tmin, tmax] (conservatively, see
// above); `entry` is where it enters. r.usable must hold. fminf / fmaxf
// return the other operand for a NaN one, on the device and the host alike.
RF_HDI bool fma_slab_test(const FmaSlabRay& r, const Box3f& box, float tmin, float tmax, float& entry) {
    const float tx0 = fmaf(box.lo.x, r.idir.x, -r.ood_lo.x);
    const float tx1 = fmaf(box.hi.x, r.idir.x, -r.ood_hi.x);
    const float ty0 = fmaf(box.lo.y, r.idir.y, -r.ood_lo.y);
    const float ty1 = fmaf(box.hi.y, r.idir.y, -r.ood_hi.y);
    const float tz0 = fmaf(box.lo.z, r.idir.z, -r.ood_lo.z);
    const float tz1 = fmaf(box.hi.z, r.idir.z, -r.ood_hi.z);
    const float t_near = fmaxf(fmaxf(fminf(tx0, tx1), fminf(ty0, ty1)), fmaxf(fminf(tz0, tz1), tmin));
    const float t_far = fminf(fminf(fmaxf(tx0, tx1), fmaxf(ty0, ty1)), fminf(fmaxf(tz0, tz1), tmax));
    entry = t_near;
    return t_near <= fmaf(t_far, kSlabFarScale, r.pad);
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
    if constexpr (kCount) {
        ++counters->nodes_visited;
        ++counters->node_fetches;
    }
    if (!slab_test(slab, bvh.nodes[0].bounds, tmin, tmax, entry)) return hit;

    StackEntry stack[kBvhMaxDepth];  // one far child per inner node on the path
    int stack_size = 0;
    uint32_t current = 0;
    for (;;) {
        const BvhNode& node = bvh.nodes[current];
        if (!node.is_leaf()) {
            if constexpr (kCount) ++counters->node_fetches;  // the children's adjacent records
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
            if (next.entry <= widen_far(tmax)) {
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
