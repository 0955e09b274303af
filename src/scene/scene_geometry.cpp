#include "rayforge/scene/scene_geometry.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {

namespace {

// World-space triangles of one instance into triangles[base ..]; a hidden
// instance's triangles all collapse onto its origin (zero area: never hit).
void write_instance(const Scene& scene, uint32_t inst_id, size_t base, SceneGeometry& g) {
    const Instance& inst = scene.instances[inst_id];
    const Mesh& mesh = scene.meshes[inst.mesh];
    const Vec3f origin = inst.transform.transform_point(Vec3f(0.0f));
    parallel::for_range(size_t(0), mesh.triangle_count(), size_t(4096), [&](size_t lo, size_t hi) {
        for (size_t t = lo; t != hi; ++t) {
            const uint32_t* idx = &mesh.indices[3 * t];
            Triangle& tri = g.triangles[base + t];
            if (!inst.visible) {
                tri = Triangle{origin, origin, origin};
                continue;
            }
            tri.v0 = inst.transform.transform_point(mesh.positions[idx[0]]);
            tri.v1 = inst.transform.transform_point(mesh.positions[idx[1]]);
            tri.v2 = inst.transform.transform_point(mesh.positions[idx[2]]);
        }
    });
}

Box3f checked_bounds(std::span<const Triangle> triangles, size_t base) {
    Box3f bounds;
    for (size_t t = 0; t < triangles.size(); ++t) {
        const Triangle& tri = triangles[t];
        if (!is_finite(tri.v0) || !is_finite(tri.v1) || !is_finite(tri.v2))
            throw Error("triangle " + std::to_string(base + t) + " has a non-finite world-space coordinate");
        bounds.extend(tri.bounds());
    }
    return bounds;
}

}  // namespace

void SceneGeometry::update_materials(const Scene& scene) {
    if (instance_first_triangle.size() != scene.instances.size() + 1)
        throw Error("scene geometry: " + std::to_string(scene.instances.size()) + " instances, flattened with " +
                    std::to_string(instance_first_triangle.size() - 1) + " (the triangles changed: flatten again)");
    const auto ids_of = [&](uint32_t inst_id) -> const std::vector<uint32_t>& {
        return scene.meshes[scene.instances[inst_id].mesh].material_ids;
    };
    for (uint32_t inst_id = 0; inst_id < scene.instances.size(); ++inst_id) {  // all checked before any is written
        const size_t flattened = instance_first_triangle[inst_id + 1] - instance_first_triangle[inst_id];
        if (ids_of(inst_id).size() != flattened)
            throw Error("mesh '" + scene.meshes[scene.instances[inst_id].mesh].name + "': " +
                        std::to_string(ids_of(inst_id).size()) + " material ids for " + std::to_string(flattened) +
                        " flattened triangles (the triangles changed: flatten again)");
    }
    for (uint32_t inst_id = 0; inst_id < scene.instances.size(); ++inst_id)
        std::copy(ids_of(inst_id).begin(), ids_of(inst_id).end(), material.begin() + instance_first_triangle[inst_id]);
    find_emitters(scene);
}

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
    g.instance_first_triangle.reserve(scene.instances.size() + 1);

    size_t base = 0;
    for (uint32_t inst_id = 0; inst_id < scene.instances.size(); ++inst_id) {
        const Instance& inst = scene.instances[inst_id];
        const Mesh& mesh = scene.meshes[inst.mesh];
        g.normal_matrices.push_back(inst.transform.normal_matrix());
        g.instance_first_triangle.push_back(uint32_t(base));
        write_instance(scene, inst_id, base, g);
        const size_t count = mesh.triangle_count();
        parallel::for_range(size_t(0), count, size_t(4096), [&](size_t lo, size_t hi) {
            for (size_t t = lo; t != hi; ++t) {
                g.triangle_instance[base + t] = inst_id;
                g.local_triangle[base + t] = uint32_t(t);
                g.material[base + t] = mesh.material_ids[t];
            }
        });
        base += count;
    }
    g.instance_first_triangle.push_back(uint32_t(base));
    g.bounds = checked_bounds(g.triangles, 0);
    g.find_emitters(scene);
    return g;
}

void SceneGeometry::find_emitters(const Scene& scene) {
    emissive_triangles.clear();
    for (size_t t = 0; t < triangles.size(); ++t) {
        if (scene.materials[material[t]].is_emissive() && triangles[t].area() > 0.0f)
            emissive_triangles.push_back(uint32_t(t));
    }
}

void SceneGeometry::update(const Scene& scene, const GeometryChange& change) {
    if (instance_first_triangle.size() != scene.instances.size() + 1)
        throw Error("scene geometry update: the scene has " + std::to_string(scene.instances.size()) +
                    " instances, the geometry was built for " +
                    std::to_string(instance_first_triangle.size() - 1));
    for (uint32_t inst_id : change.instances) {
        if (inst_id >= scene.instances.size())
            throw Error("scene geometry update: instance " + std::to_string(inst_id) + " does not exist");
        const size_t base = instance_first_triangle[inst_id];
        const size_t count = instance_first_triangle[inst_id + 1] - base;
        if (scene.meshes[scene.instances[inst_id].mesh].triangle_count() != count)
            throw Error("scene geometry update: instance " + std::to_string(inst_id) +
                        " changed its triangle count");
        normal_matrices[inst_id] = scene.instances[inst_id].transform.normal_matrix();
        write_instance(scene, inst_id, base, *this);
    }
    if (!change.geometry()) return;
    bounds = checked_bounds(triangles, 0);
    // Emitters that moved keep their place in the list; ones shown or hidden
    // (zero area) enter or leave it.
    const bool emitters = std::any_of(scene.materials.begin(), scene.materials.end(),
                                      [](const Material& m) { return m.is_emissive(); });
    if (emitters) find_emitters(scene);
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
    s.material = geometry.material[prim];
    if (mesh.uvs.empty()) return s;
    const Vec2f t0 = mesh.uvs[idx[0]], t1 = mesh.uvs[idx[1]], t2 = mesh.uvs[idx[2]];
    s.uv = t0 * w + t1 * hit.u + t2 * hit.v;

    const Vec2f duv1 = t1 - t0, duv2 = t2 - t0;
    const float uv_cross = duv1.x * duv2.y - duv1.y * duv2.x;  // twice the signed uv area
    if (len > 0.0f && std::isfinite(uv_cross)) s.uv_area_ratio = std::fabs(uv_cross) / len;
    // Only normal maps need the tangent frame.
    if (s.material >= scene.materials.size() || scene.materials[s.material].normal_texture == kNoTexture) return s;
    if (!mesh.tangents.empty()) {
        const Vec4f& a = mesh.tangents[idx[0]];
        const Vec4f& b = mesh.tangents[idx[1]];
        const Vec4f& c = mesh.tangents[idx[2]];
        Vec3f t = Vec3f(a.x, a.y, a.z) * w + Vec3f(b.x, b.y, b.z) * hit.u + Vec3f(c.x, c.y, c.z) * hit.v;
        t = scene.instances[inst_id].transform.transform_vector(t);
        const float tl = length(t);
        if (tl > 0.0f && std::isfinite(tl)) {
            s.tangent = t / tl;
            s.tangent_sign = a.w < 0.0f ? -1.0f : 1.0f;
        }
    } else if (uv_cross != 0.0f && std::isfinite(uv_cross)) {
        // dp/du and dp/dv from the triangle's edges (Lengyel's construction).
        // glTF's v grows downwards while normal maps have +y up, so the
        // bitangent follows -dp/dv.
        const Vec3f e1 = tri.v1 - tri.v0, e2 = tri.v2 - tri.v0;
        const float inv = 1.0f / uv_cross;
        const Vec3f dpdu = (e1 * duv2.y - e2 * duv1.y) * inv;
        const Vec3f dpdv = (e2 * duv1.x - e1 * duv2.x) * inv;
        const float tl = length(dpdu);
        if (tl > 0.0f && std::isfinite(tl)) {
            s.tangent = dpdu / tl;
            s.tangent_sign = dot(cross(s.shading_normal, s.tangent), -dpdv) < 0.0f ? -1.0f : 1.0f;
        }
    }
    return s;
}

}  // namespace rf
