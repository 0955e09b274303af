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
#include "trace/aila_laine_traversal.h"
#include "trace/bvh_traversal.h"
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
};

struct Bvh2Tracer {
    BvhView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return bvh_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return bvh_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        TraversalCounters t;
        Hit h;
        if (any_hit) h.prim = bvh_occluded_counted(bvh, ray, t) ? 0u : kInvalidId;
        else h = bvh_intersect_counted(bvh, ray, t);
        c.steps += t.nodes_visited;
        c.prim_tests += t.prims_tested;
        return h;
    }
};

struct AilaLaineTracer {
    AilaLaineView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return aila_laine_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return aila_laine_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        TraversalCounters t;
        Hit h;
        if (any_hit) h.prim = aila_laine_occluded_counted(bvh, ray, t) ? 0u : kInvalidId;
        else h = aila_laine_intersect_counted(bvh, ray, t);
        c.steps += t.nodes_visited;
        c.prim_tests += t.prims_tested;
        return h;
    }
};

struct CwbvhTracer {
    CwbvhView bvh;
    RF_HDI Hit intersect(const Ray& ray) const { return cwbvh_intersect(bvh, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return cwbvh_occluded(bvh, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        TraversalCounters t;
        Hit h;
        if (any_hit) h.prim = cwbvh_occluded_counted(bvh, ray, t) ? 0u : kInvalidId;
        else h = cwbvh_intersect_counted(bvh, ray, t);
        c.steps += t.nodes_visited;
        c.prim_tests += t.prims_tested;
        return h;
    }
};

template <KdTraversal kMode>
struct KdTracer {
    KdTreeView tree;
    RF_HDI Hit intersect(const Ray& ray) const { return kdtree_intersect<kMode>(tree, ray); }
    RF_HDI bool occluded(const Ray& ray) const { return kdtree_occluded<kMode>(tree, ray); }
    RF_HDI Hit counted(const Ray& ray, bool any_hit, RayCounters& c) const {
        KdTraversalCounters t;
        Hit h;
        if (any_hit) h.prim = kdtree_occluded_counted<kMode>(tree, ray, t) ? 0u : kInvalidId;
        else h = kdtree_intersect_counted<kMode>(tree, ray, t);
        c.steps += t.nodes_visited;
        c.prim_tests += t.prims_tested;
        c.restarts += t.restarts;
        return h;
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
        GridTraversalCounters t;
        Hit h;
        if (any_hit) h.prim = grid_occluded_counted(grid, ray, t) ? 0u : kInvalidId;
        else h = grid_intersect_counted(grid, ray, t);
        c.steps += t.cells_visited;
        c.prim_tests += t.prims_tested;
        return h;
    }
};

}  // namespace rf
