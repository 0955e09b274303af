// Closest-hit and any-hit traversal of the node-pair layout of Aila and Laine
// 2009, "Understanding the Efficiency of Ray Traversal on GPUs"
// (accel/bvh/layout/aila_laine_layout.h), written once for the host and the
// CUDA backend: plain pointers in, no std containers, no exceptions.
//
// The loop structure is the paper's speculative "while-while": an inner loop
// walks node pairs, postponing the first leaf it meets, until the warp's rays
// all hold a leaf (or the stack is empty), then a leaf loop tests the leaves'
// triangles up to their sentinels, and the outer loop repeats; on a GPU this keeps a warp's rays in the same phase longer
// than one loop that does either per iteration. Both children's boxes come
// from the one 64-byte node; when both are entered the nearer is taken and
// the farther pushed. As in the paper the stack holds links only (no entry
// distances), so a popped subtree's own boxes are re-tested against the
// shrunken tmax, but a popped leaf is always tested. The state lives in a
// struct (AilaLaineRayState) so that a ray can leave the loop between leaf
// phases and resume later: the 2012 addendum's dynamic fetch, which lets a
// persistent warp refill its terminated lanes (backend/cuda/device_tracer.cu).
//
// Box tests are the canonical traversal's robust slab test (Ize 2013, see
// trace/bvh_traversal.h) and triangles go through the scalar watertight test
// on their original vertices, so hits are those of the canonical BVH and the
// brute-force reference, t, u, v included.
#pragma once

#include <cstdint>
#include <cstring>

#include "accel/bvh/layout/aila_laine_layout.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/bvh_traversal.h"
#include "trace/triangle_intersect.h"

namespace rf {

namespace detail {

// Box of child `side` (0 or 1) of a node pair.
RF_HDI Box3f aila_laine_child_box(const AilaLaineNode& n, int side) {
    const AilaLaineFloat4& xy = side == 0 ? n.xy0 : n.xy1;
    Box3f box;
    box.lo = Vec3f(xy.x, xy.z, side == 0 ? n.z.x : n.z.z);
    box.hi = Vec3f(xy.y, xy.w, side == 0 ? n.z.y : n.z.w);
    return box;
}

}  // namespace detail

// Speculative traversal (Aila and Laine 2009, sec. 4): when the inner loop
// reaches a leaf, the leaf is postponed and the ray keeps walking node pairs
// until every ray of its warp holds a leaf, so that the warp enters the leaf
// loop together instead of serialising node and leaf phases. The vote is a
// policy: on the device a warp vote; on the host one ray is its own warp, so
// it stops at the first leaf (the plain while-while order). This vote never
// asks the traversal to yield (see AilaLaineDynamicFetchVote).
struct AilaLaineWarpVote {
    // True while some ray of the warp has not found a leaf yet.
    RF_HDI static bool any_searching(bool searching) {
#if defined(__CUDA_ARCH__)
        return __any_sync(__activemask(), searching);
#else
        return searching;
#endif
    }
    RF_HDI static bool yield_for_refill() { return false; }
};

// Dynamic fetch (Aila, Laine and Karras 2012, "Understanding the Efficiency
// of Ray Traversal on GPUs - Kepler and Fermi Addendum"): once most rays of
// a warp have terminated, the few still traversing leave the loop after their
// leaf phase, keeping their state, so that the terminated lanes can fetch new
// rays and the warp runs full again; the survivors resume where they were.
// The addendum's Kepler kernel used a threshold of 20 of 32 lanes.
inline constexpr int kAilaLaineDynamicFetchThreshold = 20;

struct AilaLaineDynamicFetchVote : AilaLaineWarpVote {
    // True when fewer than the threshold of the warp's lanes are still
    // traversing (the terminated ones wait at the loop's exit).
    RF_HDI static bool yield_for_refill() {
#if defined(__CUDA_ARCH__)
        return __popc(__activemask()) < kAilaLaineDynamicFetchThreshold;
#else
        return false;
#endif
    }
};

// Everything one ray's traversal needs to stop and resume: the transformed
// ray, the link stack, the current and postponed links and the hit so far.
struct AilaLaineRayState {
    detail::SlabRay slab;
    WatertightRay tri_ray;
    float tmin;
    float tmax;
    // At most one far child per inner node on the current path, over the
    // sentinel that ends the traversal when popped.
    int32_t stack[kBvhMaxDepth + 1];
    int top;
    int32_t node;
    // The postponed leaf; any non-negative value means "none" (the paper's leafAddr).
    int32_t postponed;
    Hit hit;

    RF_HDI bool finished() const { return node == kAilaLaineEntrySentinel && postponed >= 0; }
};

RF_HDI void aila_laine_begin(const AilaLaineView& bvh, const Ray& ray, AilaLaineRayState& s) {
    s.slab = detail::SlabRay::make(ray);
    s.tri_ray = WatertightRay::make(ray);
    s.tmin = ray.tmin;
    s.tmax = ray.tmax;
    s.stack[0] = kAilaLaineEntrySentinel;
    s.top = 0;
    s.node = bvh.root;  // the sentinel for an empty BVH: finished at once
    s.postponed = 0;
    s.hit = Hit{};
}

// Runs the traversal in `s` until it is finished (returns true; s.hit is the
// result) or Vote::yield_for_refill() asks it to stop after a leaf phase
// (returns false; call again to resume). Closest hit (kAnyHit = false) or
// first hit (kAnyHit = true); Vote::any_searching decides when the inner loop
// hands its postponed leaf to the leaf loop.
template <bool kAnyHit, bool kCount, class Vote = AilaLaineWarpVote>
RF_HDI bool aila_laine_resume(const AilaLaineView& bvh, AilaLaineRayState& s, TraversalCounters* counters) {
    int32_t* const stack = s.stack;
    int top = s.top;
    int32_t node = s.node;
    int32_t postponed = s.postponed;
    float tmax = s.tmax;

    while (node != kAilaLaineEntrySentinel) {
        // Inner loop: node >= 0 and below the sentinel is a node pair (a
        // negative link is huge as unsigned, so leaves end the loop too).
        while (static_cast<uint32_t>(node) < static_cast<uint32_t>(kAilaLaineEntrySentinel)) {
            const AilaLaineNode& pair = bvh.nodes[node];
            float entry0, entry1;
            const bool hit0 = detail::slab_test(s.slab, detail::aila_laine_child_box(pair, 0), s.tmin, tmax, entry0);
            const bool hit1 = detail::slab_test(s.slab, detail::aila_laine_child_box(pair, 1), s.tmin, tmax, entry1);
            if constexpr (kCount) counters->nodes_visited += 2;
            if (!hit0 && !hit1) {
                node = stack[top--];
            } else {
                int32_t near_link = hit0 ? pair.link[0] : pair.link[1];
                if (hit0 && hit1) {
                    int32_t far_link = pair.link[1];
                    if (entry1 < entry0) {  // ties go to child 0, as in the canonical traversal
                        far_link = near_link;
                        near_link = pair.link[1];
                    }
                    stack[++top] = far_link;
                }
                node = near_link;
            }
            // Postpone the first leaf met and keep descending; a second leaf ends the loop.
            if (node < 0 && postponed >= 0) {
                postponed = node;
                node = stack[top--];
            }
            if (!Vote::any_searching(postponed >= 0)) break;
        }
        // Leaf loop: the postponed leaf, then any leaf the inner loop stopped
        // on, each tested up to its sentinel. (A root that is itself a leaf
        // never enters the inner loop: it is taken here.)
        if (postponed >= 0 && node < 0) {
            postponed = node;
            node = stack[top--];
        }
        while (postponed < 0) {
            for (int32_t i = ~postponed;; i += kAilaLaineTriangleStride) {
                const AilaLaineFloat4 a = bvh.triangles[i];
                const uint32_t prim = float_to_bits(a.w);
                if (prim == kAilaLaineLeafEndW) break;
                const AilaLaineFloat4 b = bvh.triangles[i + 1];
                const AilaLaineFloat4 c = bvh.triangles[i + 2];
                const Triangle tri{Vec3f(a.x, a.y, a.z), Vec3f(b.x, b.y, b.z), Vec3f(c.x, c.y, c.z)};
                if constexpr (kCount) ++counters->prims_tested;
                TriangleHit candidate;
                if (intersect_triangle(s.tri_ray, tri, s.tmin, tmax, candidate)) {
                    s.hit.t = candidate.t;
                    s.hit.u = candidate.u;
                    s.hit.v = candidate.v;
                    s.hit.prim = prim;
                    if constexpr (kAnyHit) {  // any-hit: the first hit ends it
                        s.node = kAilaLaineEntrySentinel;
                        s.postponed = 0;
                        return true;
                    }
                    tmax = candidate.t;  // later boxes and triangles must beat it
                }
            }
            postponed = node;  // a leaf the inner loop stopped on, or ">= 0": done
            if (node < 0) node = stack[top--];
        }
        // Dynamic fetch: between leaf phases (postponed >= 0 here) the state
        // is complete, so the ray can step aside for the warp's refill.
        if (node != kAilaLaineEntrySentinel && Vote::yield_for_refill()) {
            s.top = top;
            s.node = node;
            s.postponed = postponed;
            s.tmax = tmax;
            return false;
        }
    }
    s.top = top;
    s.node = node;
    s.postponed = postponed;
    s.tmax = tmax;
    return true;
}

namespace detail {

// One ray from start to end (a vote that yields just resumes at once).
template <bool kAnyHit, bool kCount, class Vote = AilaLaineWarpVote>
RF_HDI Hit aila_laine_traverse(const AilaLaineView& bvh, const Ray& ray, TraversalCounters* counters) {
    AilaLaineRayState state;
    aila_laine_begin(bvh, ray, state);
    while (!aila_laine_resume<kAnyHit, kCount, Vote>(bvh, state, counters)) {
    }
    return state.hit;
}

}  // namespace detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim is the triangle index the
// layout was converted with.
RF_HDI Hit aila_laine_intersect(const AilaLaineView& bvh, const Ray& ray) {
    return detail::aila_laine_traverse<false, false>(bvh, ray, nullptr);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
RF_HDI bool aila_laine_occluded(const AilaLaineView& bvh, const Ray& ray) {
    return detail::aila_laine_traverse<true, false>(bvh, ray, nullptr).found();
}

// Counting variants, for traversal statistics (counters are accumulated).
RF_HDI Hit aila_laine_intersect_counted(const AilaLaineView& bvh, const Ray& ray, TraversalCounters& counters) {
    return detail::aila_laine_traverse<false, true>(bvh, ray, &counters);
}
RF_HDI bool aila_laine_occluded_counted(const AilaLaineView& bvh, const Ray& ray, TraversalCounters& counters) {
    return detail::aila_laine_traverse<true, true>(bvh, ray, &counters).found();
}

}  // namespace rf
