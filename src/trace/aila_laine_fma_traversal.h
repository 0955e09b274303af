// The aila-laine-fma variant of the node-pair traversal (GpuKernel::AilaLaineFma):
// the speculative while-while loop of Aila and Laine 2009, "Understanding the
// Efficiency of Ray Traversal on GPUs" (sec. 4), with the dynamic fetch of the
// 2012 addendum (Aila, Laine and Karras, "... Kepler and Fermi Addendum"), as
// in trace/aila_laine_traversal.h, whose loop, votes and leaf test it shares
// (detail::aila_laine_run). What differs is how a node pair is tested, as the
// paper's kernels do it (see ../shared/docs/reviews/GPU-PERFORMANCE-REVIEW.md,
// section 3, A1-A3):
//  - the ray lives in registers across the loop: resume copies the box ray,
//    the triangle ray, tmin and the hit out of the state, so only the stack
//    stays in (local) memory; the classic loop reads them through the state;
//  - boxes by the FMA min/max slab test (detail::fma_slab_test in
//    trace/bvh_traversal.h: t = fma(plane, idir, -org*idir), near and far by
//    fminf/fmaxf, the Ize far scale and a per-ray absolute pad, conservative);
//  - the 64-byte pair loaded as four 16-byte vectors (through the read-only
//    path, __ldg, on the device) into registers, the links included, so no
//    select picks between two loads.
// Rays with a zero (or subnormal) direction component cannot use the FMA
// form (FmaSlabRay::usable, see bvh_traversal.h); they run the same loop with
// the classic robust slab test, chosen once per resume. Both tests are
// conservative and triangles go through the same watertight test in the
// same order rules, so the hits are those of the classic traversal and of
// brute force, t, u, v and prim bit for bit (only which boxes are culled
// may differ, and only by entering more).
#pragma once

#include <cstdint>

#include "accel/bvh/layout/aila_laine_layout.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "trace/aila_laine_traversal.h"
#include "trace/bvh_traversal.h"

namespace rf {

namespace detail {

// The classic box ray of a ray the FMA form cannot serve: idir is 1/dir
// exactly as SlabRay::make's inv_dir, the origin the triangle ray's.
RF_HDI SlabRay exact_slab_ray(const FmaSlabRay& r, const Vec3f& org) {
    SlabRay s;
    s.org = org;
    s.inv_dir = r.idir;
    s.neg_x = r.idir.x < 0.0f;
    s.neg_y = r.idir.y < 0.0f;
    s.neg_z = r.idir.z < 0.0f;
    return s;
}

// The box test of either box ray.
RF_HDI bool pair_box_test(const FmaSlabRay& r, const Box3f& box, float tmin, float tmax, float& entry) {
    return fma_slab_test(r, box, tmin, tmax, entry);
}
RF_HDI bool pair_box_test(const SlabRay& r, const Box3f& box, float tmin, float tmax, float& entry) {
    return slab_test(r, box, tmin, tmax, entry);
}

// One node pair in registers.
struct AilaLainePairRegs {
    AilaLaineFloat4 xy0, xy1, z;
    int32_t link[2];

    RF_HDI Box3f box0() const { return {Vec3f(xy0.x, xy0.z, z.x), Vec3f(xy0.y, xy0.w, z.y)}; }
    RF_HDI Box3f box1() const { return {Vec3f(xy1.x, xy1.z, z.z), Vec3f(xy1.y, xy1.w, z.w)}; }
};

// Four 16-byte loads (the read-only path on the device).
RF_HDI AilaLainePairRegs load_aila_laine_pair(const AilaLaineNode* nodes, int32_t index) {
#if defined(__CUDA_ARCH__)
    const float4* p = reinterpret_cast<const float4*>(nodes + index);
    const float4 a = __ldg(p);
    const float4 b = __ldg(p + 1);
    const float4 c = __ldg(p + 2);
    const int4 l = __ldg(reinterpret_cast<const int4*>(p + 3));
    return {{a.x, a.y, a.z, a.w}, {b.x, b.y, b.z, b.w}, {c.x, c.y, c.z, c.w}, {l.x, l.y}};
#else
    const AilaLaineNode& n = nodes[index];
    return {n.xy0, n.xy1, n.z, {n.link[0], n.link[1]}};
#endif
}

// A node pair by the FMA slab test (BoxRay = FmaSlabRay) or, for rays it
// cannot serve, by the classic one (BoxRay = SlabRay); the pair in registers.
template <class BoxRay>
struct AilaLaineRegisterPairs {
    BoxRay ray;

    template <bool kCount>
    RF_HDI int32_t step(const AilaLaineView& bvh, int32_t node, const float& tmin, float tmax, int32_t* stack,
                        int& top, TraversalCounters* counters) const {
        const AilaLainePairRegs pair = load_aila_laine_pair(bvh.nodes, node);
        float entry0, entry1;
        const bool hit0 = pair_box_test(ray, pair.box0(), tmin, tmax, entry0);
        const bool hit1 = pair_box_test(ray, pair.box1(), tmin, tmax, entry1);
        if constexpr (kCount) {
            counters->nodes_visited += 2;
            ++counters->node_fetches;
        }
        return aila_laine_step(hit0, hit1, entry0, entry1, pair.link, stack, top);
    }
};

}  // namespace detail

using AilaLaineFmaRayState = AilaLaineState<detail::FmaSlabRay>;

RF_HDI void aila_laine_fma_begin(const AilaLaineView& bvh, const Ray& ray, AilaLaineFmaRayState& s) {
    s.slab = detail::FmaSlabRay::make(ray);
    detail::aila_laine_start(bvh, ray, s);
}

// As aila_laine_resume, with the ray in registers and the FMA box test.
template <bool kAnyHit, bool kCount, class Vote = AilaLaineWarpVote>
RF_HDI bool aila_laine_fma_resume(const AilaLaineView& bvh, AilaLaineFmaRayState& s, TraversalCounters* counters) {
    const WatertightRay tri_ray = s.tri_ray;
    const float tmin = s.tmin;
    Hit hit = s.hit;
    bool finished;
    if (s.slab.usable) {
        const detail::AilaLaineRegisterPairs<detail::FmaSlabRay> pairs{s.slab};
        finished = detail::aila_laine_run<kAnyHit, kCount, Vote>(bvh, pairs, tri_ray, tmin, hit, s, counters);
    } else {
        const detail::AilaLaineRegisterPairs<detail::SlabRay> pairs{detail::exact_slab_ray(s.slab, tri_ray.org)};
        finished = detail::aila_laine_run<kAnyHit, kCount, Vote>(bvh, pairs, tri_ray, tmin, hit, s, counters);
    }
    s.hit = hit;
    return finished;
}

// The variant as the persistent kernel and its host replays take it.
struct AilaLaineFmaTraversal {
    using State = AilaLaineFmaRayState;
    RF_HDI static void begin(const AilaLaineView& bvh, const Ray& ray, State& s) { aila_laine_fma_begin(bvh, ray, s); }
    template <bool kAnyHit, bool kCount, class Vote>
    RF_HDI static bool resume(const AilaLaineView& bvh, State& s, TraversalCounters* counters) {
        return aila_laine_fma_resume<kAnyHit, kCount, Vote>(bvh, s, counters);
    }
};

namespace detail {

// One ray from start to end (a vote that yields just resumes at once).
template <bool kAnyHit, bool kCount, class Vote = AilaLaineWarpVote>
RF_HDI Hit aila_laine_fma_traverse(const AilaLaineView& bvh, const Ray& ray, TraversalCounters* counters) {
    AilaLaineFmaRayState state;
    aila_laine_fma_begin(bvh, ray, state);
    while (!aila_laine_fma_resume<kAnyHit, kCount, Vote>(bvh, state, counters)) {
    }
    return state.hit;
}

}  // namespace detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim is the triangle index the
// layout was converted with.
RF_HDI Hit aila_laine_fma_intersect(const AilaLaineView& bvh, const Ray& ray) {
    return detail::aila_laine_fma_traverse<false, false>(bvh, ray, nullptr);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
RF_HDI bool aila_laine_fma_occluded(const AilaLaineView& bvh, const Ray& ray) {
    return detail::aila_laine_fma_traverse<true, false>(bvh, ray, nullptr).found();
}

// Counting variants, for traversal statistics (counters are accumulated).
RF_HDI Hit aila_laine_fma_intersect_counted(const AilaLaineView& bvh, const Ray& ray, TraversalCounters& counters) {
    return detail::aila_laine_fma_traverse<false, true>(bvh, ray, &counters);
}
RF_HDI bool aila_laine_fma_occluded_counted(const AilaLaineView& bvh, const Ray& ray, TraversalCounters& counters) {
    return detail::aila_laine_fma_traverse<true, true>(bvh, ray, &counters).found();
}

}  // namespace rf
