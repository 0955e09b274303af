#include "render/shading_triangles.h"

#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"

namespace rf {

ShadingTriangle make_shading_triangle(std::span<const Vec3f> normals, std::span<const Vec2f> uvs,
                                      const Affine3f& normal_matrix, const Triangle& tri, const uint32_t idx[3],
                                      uint32_t material) {
    ShadingTriangle r;
    Vec3f ng = tri.geometric_normal();
    float len = length(ng);
    r.geometric_normal = len > 0.0f ? ng / len : Vec3f{0, 0, 1};
    r.material = material;
    if (!normals.empty()) {
        r.flags |= kHasNormals;
        for (int k = 0; k < 3; ++k) {
            Vec3f n = normal_matrix.transform_vector(normals[idx[k]]);
            float nl = length(n);
            // A null or broken vertex normal falls back to the face's.
            r.normals[k] = encode_octahedral(nl > 0.0f && is_finite(nl) ? n / nl : r.geometric_normal);
        }
    }
    if (!uvs.empty()) {
        r.flags |= kHasUvs;
        for (int k = 0; k < 3; ++k) r.uv[k] = uvs[idx[k]];
        const Vec2f d1 = r.uv[1] - r.uv[0], d2 = r.uv[2] - r.uv[0];
        const float uv_cross = d1.x * d2.y - d1.y * d2.x;
        if (len > 0.0f && is_finite(uv_cross)) r.uv_area_ratio = fabsf(uv_cross) / len;
    }
    return r;
}

std::vector<ShadingTriangle> build_shading_triangles(const Scene& scene, const SceneGeometry& geometry) {
    std::vector<ShadingTriangle> records;
    budgeted_resize(records, geometry.size(), "shading attributes (64 bytes per triangle)");
    parallel::for_range(size_t(0), geometry.size(), size_t(4096), [&](size_t lo, size_t hi) {
        for (size_t prim = lo; prim < hi; ++prim) {
            ShadingTriangle& r = records[prim];
            const Triangle& tri = geometry.triangles[prim];
            const uint32_t instance = geometry.triangle_instance[prim];
            const Mesh& mesh = scene.meshes[scene.instances[instance].mesh];
            const uint32_t* idx = &mesh.indices[3 * size_t(geometry.local_triangle[prim])];
            r = make_shading_triangle(mesh.normals, mesh.uvs, geometry.normal_matrices[instance], tri, idx,
                                      geometry.material[prim]);
            if (r.flags & kHasUvs) {
                // The tangent frame of normal maps, as surface_at derives it
                // at the triangle's centre.
                const uint32_t material = r.material;
                if (material < scene.materials.size() && scene.materials[material].normal_texture != kNoTexture) {
                    Ray ray;
                    ray.org = tri.centroid() - r.geometric_normal;
                    ray.dir = r.geometric_normal;
                    Hit centre;
                    centre.t = 1.0f;
                    centre.u = centre.v = 1.0f / 3.0f;
                    centre.prim = uint32_t(prim);
                    const SurfaceHit s = surface_at(scene, geometry, ray, centre);
                    if (s.tangent_sign != 0.0f) {
                        r.tangent = encode_octahedral(s.tangent);
                        r.flags |= kHasTangent | (s.tangent_sign < 0.0f ? kNegativeBitangent : 0u);
                    }
                }
            }
        }
    });
    return records;
}

}  // namespace rf
