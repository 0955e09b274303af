// Closest-hit and any-hit traversal of a two-level structure (instancing):
// a top-level canonical BVH over the world boxes of the visible instances,
// whose leaves name instances, and one bottom-level structure per mesh in
// the mesh's object space. Written once for the host and the CUDA backend
// over plain pointers, like trace/bvh_traversal.h.
//
// At a top-level leaf the ray is taken into the instance's object space by
// the stored inverse transform (origin as a point, direction as a vector,
// not renormalised), so a hit's t is the same number in both spaces and the
// closest hit so far bounds the next instance's search directly (tmax).
// The bottom level answers with its local triangle index; the flat
// SceneGeometry index is the instance's first triangle plus that.
//
// The bottom-level trace is a template parameter with
//   Hit intersect(const BlasView&, const Ray&) const;
//   bool occluded(const BlasView&, const Ray&) const;
// Bvh2Blas (below) is the RF_HD one over BvhView; the CPU accel plugs in
// the SIMD BVH4/8 traversal (accel/update/two_level_accel.cpp).
// Bvh2BlasCounted counts the bottom levels' box and triangle tests into the
// TraversalCounters the top level counts its own box tests into.
#pragma once

#include <cstdint>

#include "core/assert.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/affine.h"
#include "rayforge/math/ray.h"
#include "trace/bvh_traversal.h"
#include "trace/tracers.h"

namespace rf {

// One visible instance as the traversal sees it.
struct TwoLevelInstance {
    Affine3f world_to_object;  // the inverse of Instance::transform
    uint32_t blas = 0;         // index into TwoLevelView::blas (its mesh's structure)
    uint32_t first_triangle = 0;  // SceneGeometry::instance_first_triangle of the instance
};

// The whole structure; top_node_count == 0: every ray misses.
template <class BlasView>
struct TwoLevelView {
    const BvhNode* top_nodes = nullptr;       // canonical BVH over instance world boxes
    const uint32_t* top_prims = nullptr;      // top leaf slots -> index into instances
    uint32_t top_node_count = 0;
    const TwoLevelInstance* instances = nullptr;
    const BlasView* blas = nullptr;           // per mesh, object space
};

// The bottom level as binary BVHs (trace/bvh_traversal.h): the RF_HD choice.
struct Bvh2Blas {
    RF_HDI Hit intersect(const BvhView& bvh, const Ray& ray) const { return bvh_intersect(bvh, ray); }
    RF_HDI bool occluded(const BvhView& bvh, const Ray& ray) const { return bvh_occluded(bvh, ray); }
};

struct Bvh2BlasCounted {
    TraversalCounters* counters;
    RF_HDI Hit intersect(const BvhView& bvh, const Ray& ray) const { return bvh_intersect_counted(bvh, ray, *counters); }
    RF_HDI bool occluded(const BvhView& bvh, const Ray& ray) const { return bvh_occluded_counted(bvh, ray, *counters); }
};

// The ray in an instance's object space: same tmin and tmax (t is preserved).
RF_HDI Ray ray_to_object(const Affine3f& world_to_object, const Ray& ray) {
    Ray local;
    local.org = world_to_object.transform_point(ray.org);
    local.dir = world_to_object.transform_vector(ray.dir);
    local.tmin = ray.tmin;
    local.tmax = ray.tmax;
    return local;
}

namespace detail {

// The instances of one top-level leaf; returns true on an any-hit.
template <bool kAnyHit, class BlasView, class BlasTrace>
RF_HDI bool two_level_leaf(const TwoLevelView<BlasView>& view, const BvhNode& leaf, const Ray& ray,
                           const BlasTrace& trace, float& tmax, Hit& hit) {
    const uint32_t end = leaf.first + leaf.count;
    for (uint32_t slot = leaf.first; slot < end; ++slot) {
        const TwoLevelInstance& inst = view.instances[view.top_prims[slot]];
        Ray local = ray_to_object(inst.world_to_object, ray);
        local.tmax = tmax;
        if constexpr (kAnyHit) {
            if (trace.occluded(view.blas[inst.blas], local)) {
                hit.prim = inst.first_triangle;  // found(); which triangle is not asked
                return true;
            }
        } else {
            const Hit h = trace.intersect(view.blas[inst.blas], local);
            if (h.found()) {
                hit = h;
                hit.prim = inst.first_triangle + h.prim;
                tmax = h.t;
            }
        }
    }
    return false;
}

// The top level: nearest child first, far children on a stack with their
// entry distance (skipped once a closer hit is known), as in bvh_traversal.h.
// counters (may be null) get the top level's box tests.
template <bool kAnyHit, class BlasView, class BlasTrace>
RF_HDI Hit two_level_traverse(const TwoLevelView<BlasView>& view, const Ray& ray, const BlasTrace& trace,
                              TraversalCounters* counters = nullptr) {
    Hit hit;
    if (view.top_node_count == 0) return hit;
    const SlabRay slab = SlabRay::make(ray);
    const float tmin = ray.tmin;
    float tmax = ray.tmax;
    float entry;
    if (counters) {
        ++counters->nodes_visited;
        ++counters->node_fetches;
    }
    if (!slab_test(slab, view.top_nodes[0].bounds, tmin, tmax, entry)) return hit;

    StackEntry stack[kBvhMaxDepth];
    int stack_size = 0;
    uint32_t current = 0;
    for (;;) {
        const BvhNode& node = view.top_nodes[current];
        if (!node.is_leaf()) {
            const uint32_t left = node.first;
            RF_ASSERT(left + 1 < view.top_node_count, "a top-level node's children lie beyond the node array");
            float entry_left, entry_right;
            const bool hit_left = slab_test(slab, view.top_nodes[left].bounds, tmin, tmax, entry_left);
            const bool hit_right = slab_test(slab, view.top_nodes[left + 1].bounds, tmin, tmax, entry_right);
            if (counters) {
                counters->nodes_visited += 2;
                ++counters->node_fetches;  // the children's adjacent records, as in bvh_traversal.h
            }
            if (hit_left && hit_right) {
                const bool left_first = entry_left <= entry_right;
                current = left_first ? left : left + 1;
                RF_ASSERT(stack_size < kBvhMaxDepth, "a top level deeper than kBvhMaxDepth");
                stack[stack_size++] = left_first ? StackEntry{left + 1, entry_right} : StackEntry{left, entry_left};
                continue;
            }
            if (hit_left || hit_right) {
                current = hit_left ? left : left + 1;
                continue;
            }
        } else if (two_level_leaf<kAnyHit>(view, node, ray, trace, tmax, hit)) {
            return hit;
        }
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

// Closest hit with t in [ray.tmin, ray.tmax]; prim is the flat SceneGeometry index.
template <class BlasView, class BlasTrace>
RF_HDI Hit two_level_intersect(const TwoLevelView<BlasView>& view, const Ray& ray, const BlasTrace& trace) {
    return detail::two_level_traverse<false>(view, ray, trace);
}

// True when any visible instance is hit with t in [ray.tmin, ray.tmax].
template <class BlasView, class BlasTrace>
RF_HDI bool two_level_occluded(const TwoLevelView<BlasView>& view, const Ray& ray, const BlasTrace& trace) {
    return detail::two_level_traverse<true>(view, ray, trace).found();
}

// The tracer struct (trace/tracers.h style) over binary bottom levels: what
// a CUDA kernel takes by value.
struct TwoLevelBvh2Tracer {
    TwoLevelView<BvhView> view;
    RF_HDI Hit intersect(const Ray& ray) const { return two_level_intersect(view, ray, Bvh2Blas{}); }
    RF_HDI bool occluded(const Ray& ray) const { return two_level_occluded(view, ray, Bvh2Blas{}); }
    // Box tests of both levels and triangle tests, like Bvh2Tracer::counted.
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<TraversalCounters>(
            any_hit, c,
            [&](TraversalCounters& t) { return detail::two_level_traverse<false>(view, ray, Bvh2BlasCounted{&t}, &t); },
            [&](TraversalCounters& t) {
                return detail::two_level_traverse<true>(view, ray, Bvh2BlasCounted{&t}, &t).found();
            });
    }
};

}  // namespace rf
