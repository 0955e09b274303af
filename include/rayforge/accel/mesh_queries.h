// Queries over a triangle mesh beyond the closest hit, on the CPU: every hit
// of a ray (listed or counted), the closest point of the mesh to a point,
// and the generalised winding number (inside/outside for meshes that are
// not closed). What a Python RaycastingScene (Open3D-style) answers.
//
// The mesh is the caller's flat triangles (a SceneGeometry's, or any other);
// Hit::prim and ClosestPoint::prim index them. Every batch call runs in
// parallel over its queries on the calling thread's TBB arena (wrap it in a
// task_arena, or rf::parallel::with_threads, to limit the threads), and its
// answers do not depend on the thread count. Queries may run concurrently
// with each other, not with refit().
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Every hit of a batch of rays, ray after ray.
struct AllHits {
    std::vector<uint32_t> ray_splits;  // rays.size() + 1 prefix sums: ray i's hits are [ray_splits[i], ray_splits[i+1])
    std::vector<uint32_t> ray_ids;     // per hit: the ray's index
    std::vector<Hit> hits;             // per hit (t, u, v, prim), sorted by t (then prim) within a ray
};

// The closest point of the mesh to a query; prim == kInvalidId (and a NaN
// point) for an empty mesh or a query with a non-finite coordinate.
struct ClosestPoint {
    Vec3f point;
    uint32_t prim = kInvalidId;
    float u = 0.0f, v = 0.0f;  // barycentrics of the triangle's vertices 1 and 2 at `point`
};

class MeshQueries {
public:
    virtual ~MeshQueries() = default;

    // Over `triangles` (copied), with a canonical BVH built on the CPU by
    // `build` (its builder, leaf size, SAH costs and threads; structure,
    // layout and device ignored). Throws rf::Error for invalid options, a
    // non-finite coordinate or more than 2^31 - 1 triangles. Empty meshes are fine.
    static std::unique_ptr<MeshQueries> build(std::span<const Triangle> triangles, const BuildOptions& build = {});

    // Every hit with t in [ray.tmin, ray.tmax] (the watertight test of
    // trace/triangle_intersect.h: both facings; zero-area triangles never
    // hit), sorted by t then prim. Hits of one ray at the same distance
    // (|dt| <= 1e-6 max(1, |t|)) on triangles sharing a vertex (bit-equal
    // positions) count once, the smallest prim kept, so a ray through a
    // shared edge or vertex of a mesh crosses it once. A ray with a NaN or
    // infinite origin or direction component, a zero direction or a NaN
    // tmin/tmax has no hits. `out` is overwritten.
    virtual void list_intersections(std::span<const Ray> rays, AllHits& out) const = 0;
    // The number of hits list_intersections reports for each ray; counts.size() == rays.size().
    virtual void count_intersections(std::span<const Ray> rays, std::span<uint32_t> counts) const = 0;

    // The closest point of the triangles to each query (out.size() ==
    // queries.size()); a zero-area triangle counts as its segment or
    // point. Ties in distance: the smallest prim.
    virtual void closest_points(std::span<const Vec3f> queries, std::span<ClosestPoint> out) const = 0;

    // The generalised winding number of the triangles at each query (Jacobson
    // et al. 2013), ~1 inside a closed outward-wound mesh, ~0 outside, and
    // close to that inside a mesh with holes; NaN for a query with a
    // non-finite coordinate, 0 for an empty mesh. beta > 0: Barill et al.
    // 2018's approximation (a node farther than beta times its radius uses
    // its second-order expansion); beta <= 0: the exact sum over every
    // triangle. Zero-area triangles contribute nothing.
    virtual void winding_numbers(std::span<const Vec3f> queries, std::span<float> out, float beta = 2.0f) const = 0;

    // The triangles moved (the same count, in the same order): the BVH is
    // refitted (its topology kept) and the winding expansions recomputed.
    // Throws rf::Error for another count or a non-finite coordinate.
    virtual void refit(std::span<const Triangle> triangles) = 0;

    [[nodiscard]] virtual size_t size() const = 0;  // triangles
    [[nodiscard]] virtual const Bvh& bvh() const = 0;  // the canonical BVH (prim_indices index the triangles)
};

}  // namespace rf
