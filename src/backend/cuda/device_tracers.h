// The tracers the device integrators and trace kernels call: one small
// struct per GPU kernel (rf::GpuKernel) with the member functions the
// integrators of src/render expect (intersect, occluded), each forwarding to
// the shared host/device traversal of src/trace. Views hold device pointers.
#pragma once

#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "rayforge/core/host_device.h"
#include "trace/aila_laine_traversal.h"
#include "trace/bvh_traversal.h"
#include "trace/cwbvh_traversal.h"
#include "trace/grid_traversal.h"
#include "trace/kdtree_traversal.h"

namespace rf::cuda {

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

}  // namespace rf::cuda
