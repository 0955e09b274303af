// SceneGeometry: the scene flattened to world space, the form every
// acceleration structure is built over and every integrator shades from.
// Triangle i of the flat array is triangle `local_triangle[i]` of mesh
// `instance_mesh[triangle_instance[i]]`; Hit::prim indexes this array.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/math/affine.h"
#include "rayforge/math/box.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene.h"

namespace rf {

struct Triangle {
    Vec3f v0, v1, v2;
    RF_HDI Box3f bounds() const { Box3f b; b.extend(v0); b.extend(v1); b.extend(v2); return b; }
    RF_HDI Vec3f centroid() const { return (v0 + v1 + v2) * (1.0f / 3.0f); }
    RF_HDI Vec3f geometric_normal() const { return cross(v1 - v0, v2 - v0); }  // not normalised
    RF_HDI float area() const { return 0.5f * length(geometric_normal()); }
};

struct SceneGeometry {
    std::vector<Triangle> triangles;          // world space
    std::vector<uint32_t> triangle_instance;  // per triangle: index into Scene::instances
    std::vector<uint32_t> local_triangle;     // per triangle: index within its mesh
    std::vector<uint32_t> material;           // per triangle: index into Scene::materials
    std::vector<uint32_t> emissive_triangles; // triangles whose material emits (area lights)
    std::vector<Affine3f> normal_matrices;    // per instance
    std::vector<uint32_t> instance_first_triangle;  // per instance + 1: its triangles are [first[i], first[i+1])
    Box3f bounds;

    // Flattens every instance; throws rf::Error on non-finite coordinates or
    // more than 2^32-1 triangles. Degenerate (zero-area) triangles are kept:
    // they never produce hits.
    static SceneGeometry build(const Scene& scene);
    // Rewrites the world-space triangles of the instances `change` names
    // (after Scene::set_time), the bounds, and the emitter list (hidden
    // triangles have zero area and leave it); the triangle order, count and
    // materials stay. Throws rf::Error on non-finite coordinates.
    void update(const Scene& scene, const GeometryChange& change);
    // emissive_triangles from the materials and the current triangles (those of zero area never emit).
    void find_emitters(const Scene& scene);
    // The per-triangle materials from the meshes' material ids (after they
    // changed in place), then the emitters; the triangles stay.
    void update_materials(const Scene& scene);
    [[nodiscard]] size_t size() const { return triangles.size(); }
    [[nodiscard]] size_t memory_bytes() const;
};

// Shading attributes at a hit, interpolated from the mesh.
struct SurfaceHit {
    Vec3f position;
    Vec3f geometric_normal;  // unit, world space, as wound (not flipped to face the ray)
    Vec3f shading_normal;    // unit, interpolated vertex normal (or geometric)
    Vec2f uv;
    uint32_t material = 0;
    // Tangent frame for normal maps (filled only where the material has one):
    // unit world tangent (dp/du) and the bitangent's handedness (bitangent =
    // w * cross(shading_normal, tangent)); w == 0 when there is no normal
    // map or the mesh has neither tangents nor usable uvs.
    Vec3f tangent{0.0f, 0.0f, 0.0f};
    float tangent_sign = 0.0f;
    // Texture-space area over world-space area of the triangle (0 without
    // uvs): how many texels a unit of surface covers, for mip selection.
    float uv_area_ratio = 0.0f;
};

// Interpolates the hit's attributes; `hit` must be found().
SurfaceHit surface_at(const Scene& scene, const SceneGeometry& geometry, const Ray& ray, const Hit& hit);

}  // namespace rf
