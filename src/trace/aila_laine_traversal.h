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
// ray (BoxRay for the box test: detail::SlabRay here, the FMA form's in
// trace/aila_laine_fma_traversal.h), the link stack, the current and
// postponed links and the hit so far.
template <class BoxRay>
struct AilaLaineState {
    BoxRay slab;
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

using AilaLaineRayState = AilaLaineState<detail::SlabRay>;

namespace detail {

// Everything of a fresh state but its box ray.
template <class BoxRay>
RF_HDI void aila_laine_start(const AilaLaineView& bvh, const Ray& ray, AilaLaineState<BoxRay>& s) {
    s.tri_ray = WatertightRay::make(ray);
    s.tmin = ray.tmin;
    s.tmax = ray.tmax;
    s.stack[0] = kAilaLaineEntrySentinel;
    s.top = 0;
    s.node = bvh.root;  // the sentinel for an empty BVH: finished at once
    s.postponed = 0;
    s.hit = Hit{};
}

// Where the inner loop goes after a node pair's box tests: the nearer child
// hit (ties go to child 0, as in the canonical traversal), the farther one
// pushed; the stack's top when neither is hit.
RF_HDI int32_t aila_laine_step(bool hit0, bool hit1, float entry0, float entry1, const int32_t (&link)[2],
                               int32_t* stack, int& top) {
    if (!hit0 && !hit1) return stack[top--];
    int32_t near_link = hit0 ? link[0] : link[1];
    if (hit0 && hit1) {
        int32_t far_link = link[1];
        if (entry1 < entry0) {
            far_link = near_link;
            near_link = link[1];
        }
        stack[++top] = far_link;
    }
    return near_link;
}

// Tests the triangles of the leaf list behind `leaf` (a negative link) up to
// its sentinel, shrinking tmax and filling `hit`; with kAnyHit it stops at,
// and returns true on, the first hit.
template <bool kAnyHit, bool kCount>
RF_HDI bool aila_laine_test_leaf(const AilaLaineView& bvh, int32_t leaf, const WatertightRay& tri_ray,
                                 const float& tmin, float& tmax, Hit& hit, TraversalCounters* counters) {
    for (int32_t i = ~leaf;; i += kAilaLaineTriangleStride) {
        const AilaLaineFloat4 a = bvh.triangles[i];
        const uint32_t prim = float_to_bits(a.w);
        if (prim == kAilaLaineLeafEndW) return false;
        const AilaLaineFloat4 b = bvh.triangles[i + 1];
        const AilaLaineFloat4 c = bvh.triangles[i + 2];
        const Triangle tri{Vec3f(a.x, a.y, a.z), Vec3f(b.x, b.y, b.z), Vec3f(c.x, c.y, c.z)};
        if constexpr (kCount) ++counters->prims_tested;
        TriangleHit candidate;
        if (intersect_triangle(tri_ray, tri, tmin, tmax, candidate)) {
            hit.t = candidate.t;
            hit.u = candidate.u;
            hit.v = candidate.v;
            hit.prim = prim;
            if constexpr (kAnyHit) return true;  // any-hit: the first hit ends it
            tmax = candidate.t;  // later boxes and triangles must beat it
        }
    }
}

// The while-while loop over a state's links: runs until the traversal is
// finished (true) or Vote::yield_for_refill() asks it to stop after a leaf
// phase (false). Pairs::step tests a node pair and returns the next link
// (detail::aila_laine_step). The ray (pairs, tri_ray, tmin) and the hit are
// passed by reference: the classic traversal hands the state's own fields
// (read from memory as before), the FMA variant local copies (registers).
template <bool kAnyHit, bool kCount, class Vote, class Pairs, class BoxRay>
RF_HDI bool aila_laine_run(const AilaLaineView& bvh, const Pairs& pairs, const WatertightRay& tri_ray,
                           const float& tmin, Hit& hit, AilaLaineState<BoxRay>& s, TraversalCounters* counters) {
    int32_t* const stack = s.stack;
    int top = s.top;
    int32_t node = s.node;
    int32_t postponed = s.postponed;
    float tmax = s.tmax;

    while (node != kAilaLaineEntrySentinel) {
        // Inner loop: node >= 0 and below the sentinel is a node pair (a
        // negative link is huge as unsigned, so leaves end the loop too).
        while (static_cast<uint32_t>(node) < static_cast<uint32_t>(kAilaLaineEntrySentinel)) {
            node = pairs.template step<kCount>(bvh, node, tmin, tmax, stack, top, counters);
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
            if (aila_laine_test_leaf<kAnyHit, kCount>(bvh, postponed, tri_ray, tmin, tmax, hit, counters)) {
                s.node = kAilaLaineEntrySentinel;
                s.postponed = 0;
                return true;
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

// The classic node-pair test: the pair read where it lies, both children by
// the canonical robust slab test.
struct AilaLaineSlabPairs {
    const SlabRay& slab;

    template <bool kCount>
    RF_HDI int32_t step(const AilaLaineView& bvh, int32_t node, const float& tmin, float tmax, int32_t* stack,
                        int& top, TraversalCounters* counters) const {
        const AilaLaineNode& pair = bvh.nodes[node];
        float entry0, entry1;
        const bool hit0 = slab_test(slab, aila_laine_child_box(pair, 0), tmin, tmax, entry0);
        const bool hit1 = slab_test(slab, aila_laine_child_box(pair, 1), tmin, tmax, entry1);
        if constexpr (kCount) {
            counters->nodes_visited += 2;
            ++counters->node_fetches;
        }
        return aila_laine_step(hit0, hit1, entry0, entry1, pair.link, stack, top);
    }
};

}  // namespace detail

RF_HDI void aila_laine_begin(const AilaLaineView& bvh, const Ray& ray, AilaLaineRayState& s) {
    s.slab = detail::SlabRay::make(ray);
    detail::aila_laine_start(bvh, ray, s);
}

// Runs the traversal in `s` until it is finished (returns true; s.hit is the
// result) or Vote::yield_for_refill() asks it to stop after a leaf phase
// (returns false; call again to resume). Closest hit (kAnyHit = false) or
// first hit (kAnyHit = true); Vote::any_searching decides when the inner loop
// hands its postponed leaf to the leaf loop.
template <bool kAnyHit, bool kCount, class Vote = AilaLaineWarpVote>
RF_HDI bool aila_laine_resume(const AilaLaineView& bvh, AilaLaineRayState& s, TraversalCounters* counters) {
    const detail::AilaLaineSlabPairs pairs{s.slab};
    return detail::aila_laine_run<kAnyHit, kCount, Vote>(bvh, pairs, s.tri_ray, s.tmin, s.hit, s, counters);
}

// The traversal as the persistent kernel (backend/cuda/device_tracer.cu)
// and its host replays take it: a state, begin and resume.
struct AilaLaineTraversal {
    using State = AilaLaineRayState;
    RF_HDI static void begin(const AilaLaineView& bvh, const Ray& ray, State& s) { aila_laine_begin(bvh, ray, s); }
    template <bool kAnyHit, bool kCount, class Vote>
    RF_HDI static bool resume(const AilaLaineView& bvh, State& s, TraversalCounters* counters) {
        return aila_laine_resume<kAnyHit, kCount, Vote>(bvh, s, counters);
    }
};

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
