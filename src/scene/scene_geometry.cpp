#include "rayforge/scene/scene_geometry.h"

#include <cmath>
#include <string>

#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {

SceneGeometry SceneGeometry::build(const Scene& scene) {
    SceneGeometry g;
    const size_t total = scene.triangle_count();
    if (total >= size_t(kInvalidId))
        throw Error("scene has " + std::to_string(total) + " triangles; at most 4294967294 are supported");
    budgeted_resize(g.triangles, total, "scene geometry: triangles");
    budgeted_resize(g.triangle_instance, total, "scene geometry: triangle instances");
    budgeted_resize(g.local_triangle, total, "scene geometry: local triangle indices");
    budgeted_resize(g.material, total, "scene geometry: triangle materials");
    g.normal_matrices.reserve(scene.instances.size());

    size_t base = 0;
    for (uint32_t inst_id = 0; inst_id < scene.instances.size(); ++inst_id) {
        const Instance& inst = scene.instances[inst_id];
        const Mesh& mesh = scene.meshes[inst.mesh];
        g.normal_matrices.push_back(inst.transform.normal_matrix());
        const size_t count = mesh.triangle_count();
        parallel::for_range(size_t(0), count, size_t(4096), [&](size_t lo, size_t hi) {
            for (size_t t = lo; t != hi; ++t) {
                const uint32_t* idx = &mesh.indices[3 * t];
                Triangle& tri = g.triangles[base + t];
                tri.v0 = inst.transform.transform_point(mesh.positions[idx[0]]);
                tri.v1 = inst.transform.transform_point(mesh.positions[idx[1]]);
                tri.v2 = inst.transform.transform_point(mesh.positions[idx[2]]);
                g.triangle_instance[base + t] = inst_id;
                g.local_triangle[base + t] = uint32_t(t);
                g.material[base + t] = mesh.material_ids[t];
            }
        });
        base += count;
    }
    for (size_t t = 0; t < total; ++t) {
        const Triangle& tri = g.triangles[t];
        if (!is_finite(tri.v0) || !is_finite(tri.v1) || !is_finite(tri.v2))
            throw Error("triangle " + std::to_string(t) + " has a non-finite world-space coordinate");
        g.bounds.extend(tri.bounds());
        if (scene.materials[g.material[t]].is_emissive() && tri.area() > 0.0f)
            g.emissive_triangles.push_back(uint32_t(t));
    }
    return g;
}

size_t SceneGeometry::memory_bytes() const {
    return triangles.size() * sizeof(Triangle) +
           (triangle_instance.size() + local_triangle.size() + material.size() + emissive_triangles.size()) *
               sizeof(uint32_t) +
           normal_matrices.size() * sizeof(Affine3f);
}

SurfaceHit surface_at(const Scene& scene, const SceneGeometry& geometry, const Ray& ray, const Hit& hit) {
    const uint32_t prim = hit.prim;
    const Triangle& tri = geometry.triangles[prim];
    const uint32_t inst_id = geometry.triangle_instance[prim];
    const Mesh& mesh = scene.meshes[scene.instances[inst_id].mesh];
    const uint32_t* idx = &mesh.indices[3 * size_t(geometry.local_triangle[prim])];
    const float w = 1.0f - hit.u - hit.v;

    SurfaceHit s;
    s.position = ray.org + ray.dir * hit.t;
    Vec3f ng = tri.geometric_normal();
    float len = length(ng);
    s.geometric_normal = len > 0.0f ? ng / len : Vec3f{0, 0, 1};
    s.shading_normal = s.geometric_normal;
    if (!mesh.normals.empty()) {
        Vec3f n = mesh.normals[idx[0]] * w + mesh.normals[idx[1]] * hit.u + mesh.normals[idx[2]] * hit.v;
        n = geometry.normal_matrices[inst_id].transform_vector(n);
        float nl = length(n);
        if (nl > 0.0f && std::isfinite(nl)) s.shading_normal = n / nl;
    }
    if (!mesh.uvs.empty()) s.uv = mesh.uvs[idx[0]] * w + mesh.uvs[idx[1]] * hit.u + mesh.uvs[idx[2]] * hit.v;
    s.material = geometry.material[prim];
    return s;
}

}  // namespace rf
