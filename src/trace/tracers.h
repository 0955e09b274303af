// The tracers: one small struct per traversal over a plain view of a
// structure, with what the integrators and the batch loops call
// (intersect, occluded, and counted for the instrumented pass), each
// forwarding to the shared host/device traversal code of src/trace. The
// same structs serve both backends: on the CPU an rf::Accel wraps one
// (accel/view_accel.h) over host arrays; on the GPU the trace and render
// kernels take one by value over device arrays. The CPU-only SIMD layouts
// add theirs in backend/cpu/wide_bvh_tracer.h.
#pragma once

#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "rayforge/core/host_device.h"
#include "trace/aila_laine_fma_traversal.h"
#include "trace/aila_laine_traversal.h"
#include "trace/bvh_traversal.h"
#include "trace/cwbvh_fma_traversal.h"
#include "trace/cwbvh_traversal.h"
#include "trace/grid_traversal.h"
#include "trace/kdtree_traversal.h"
#include "trace/triangle_intersect.h"

namespace rf {

// Traversal statistics gathered per ray by the counting variants.
struct RayCounters {
    uint32_t steps = 0;       // node or cell visits
    uint32_t prim_tests = 0;  // triangle tests
    uint32_t restarts = 0;    // kd-tree restarts
    uint32_t node_fetches = 0;  // BVH node fetches (TraversalCounters::node_fetches)
};

// Each traversal's own counters, added to a RayCounters.
RF_HDI void add_counts(const TraversalCounters& t, RayCounters& c) {
    c.steps += t.nodes_visited;
    c.prim_tests += t.prims_tested;
    c.node_fetches += t.node_fetches;
}
RF_HDI void add_counts(const KdTraversalCounters& t, RayCounters& c) {
    c.steps += t.nodes_visited;
    c.prim_tests += t.prims_tested;
    c.restarts += t.restarts;
}
RF_HDI void add_counts(const GridTraversalCounters& t, RayCounters& c) {
    c.steps += t.cells_visited;
    c.prim_tests += t.prims_tested;
}

// What every tracer's counted() does: the closest-hit or any-hit traversal
// with counters (an any-hit answer is a Hit whose prim says found or not),
// the counters added to `c`.
template <class Counters, class Closest, class AnyHit>
RF_HDI Hit counted_query(bool any_hit, RayCounters& c, Closest&& closest, AnyHit&& occluded) {
    Counters t;
    Hit h;
    if (any_hit) h.prim = occluded(t) ? 0u : kInvalidId;
    else h = closest(t);
    add_counts(t, c);
    return h;
}

struct Bvh2Tracer {
    BvhView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return bvh_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return bvh_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<TraversalCounters>(
            any_hit, c, [&](TraversalCounters& t) { return bvh_intersect_counted(bvh, ray, t); },
            [&](TraversalCounters& t) { return bvh_occluded_counted(bvh, ray, t); });
    }
};

struct AilaLaineTracer {
    AilaLaineView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return aila_laine_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return aila_laine_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<TraversalCounters>(
            any_hit, c, [&](TraversalCounters& t) { return aila_laine_intersect_counted(bvh, ray, t); },
            [&](TraversalCounters& t) { return aila_laine_occluded_counted(bvh, ray, t); });
    }
};

// The aila-laine-fma variant (GpuKernel::AilaLaineFma) over the same node pairs.
struct AilaLaineFmaTracer {
    AilaLaineView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return aila_laine_fma_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return aila_laine_fma_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<TraversalCounters>(
            any_hit, c, [&](TraversalCounters& t) { return aila_laine_fma_intersect_counted(bvh, ray, t); },
            [&](TraversalCounters& t) { return aila_laine_fma_occluded_counted(bvh, ray, t); });
    }
};

struct CwbvhTracer {
    CwbvhView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return cwbvh_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return cwbvh_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<TraversalCounters>(
            any_hit, c, [&](TraversalCounters& t) { return cwbvh_intersect_counted(bvh, ray, t); },
            [&](TraversalCounters& t) { return cwbvh_occluded_counted(bvh, ray, t); });
    }
};

// The cwbvh-fma variant (GpuKernel::CwbvhFma) over the same compressed nodes.
struct CwbvhFmaTracer {
    CwbvhView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return cwbvh_fma_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return cwbvh_fma_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<TraversalCounters>(
            any_hit, c, [&](TraversalCounters& t) { return cwbvh_fma_intersect_counted(bvh, ray, t); },
            [&](TraversalCounters& t) { return cwbvh_fma_occluded_counted(bvh, ray, t); });
    }
};

template <KdTraversal kMode>
struct KdTracer {
    KdTreeView tree;
    RF_HDI Hit intersect(const Ray& ray) const { return kdtree_intersect<kMode>(tree, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return kdtree_occluded<kMode>(tree, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<KdTraversalCounters>(
            any_hit, c, [&](KdTraversalCounters& t) { return kdtree_intersect_counted<kMode>(tree, ray, t); },
            [&](KdTraversalCounters& t) { return kdtree_occluded_counted<kMode>(tree, ray, t); });
    }
};

// Every triangle for every ray: the reference every other tracer is checked
// against (no counted traversal: its work is the triangle count).
struct BruteForceTracer {
    const Triangle* triangles = nullptr;
    uint32_t count = 0;
    RF_HDI Hit intersect(const Ray& ray) const {
        const WatertightRay tri_ray = WatertightRay::make(ray);
        Hit hit;
        float tmax = ray.tmax;
        for (uint32_t i = 0; i < count; ++i) {
            TriangleHit candidate;
            if (intersect_triangle(tri_ray, triangles[i], ray.tmin, tmax, candidate)) {
                hit = Hit{candidate.t, candidate.u, candidate.v, i};
                tmax = candidate.t;
            }
        }
        return hit;
    }
    RF_HDI bool occluded(const Ray& ray) const {
        const WatertightRay tri_ray = WatertightRay::make(ray);
        for (uint32_t i = 0; i < count; ++i) {
            TriangleHit candidate;
            if (intersect_triangle(tri_ray, triangles[i], ray.tmin, ray.tmax, candidate)) return true;
        }
        return false;
    }
};

struct GridTracer {
    GridView grid;  // proximity != nullptr: proximity clouds
    RF_HDI Hit intersect(const Ray& ray) const { return grid_intersect(grid, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return grid_occluded(grid, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        return counted_query<GridTraversalCounters>(
            any_hit, c, [&](GridTraversalCounters& t) { return grid_intersect_counted(grid, ray, t); },
            [&](GridTraversalCounters& t) { return grid_occluded_counted(grid, ray, t); });
    }
};

}  // namespace rf
