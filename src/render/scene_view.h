// The integrators' view of a scene, one type for both backends: materials
// flattened to ShadingMaterial, textures with their mip chains as
// MipTextureView, every emitter as one LightSet and the shading record of
// every triangle, all behind plain pointers. On the CPU they point into a
// SceneTables (below); on the GPU into device copies of the same tables
// (backend/cuda/device_scene), so the integrators of src/render read the
// scene the same way on both.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "rayforge/core/host_device.h"
#include "core/assert.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "render/area_lights.h"
#include "render/light_set.h"
#include "render/material_eval.h"
#include "render/shading_triangles.h"
#include "render/texture_mip.h"
#include "render/texture_sampling.h"

namespace rf {

struct SceneView {
    const ShadingTriangle* shading_triangles = nullptr;
    const ShadingMaterial* materials = nullptr;  // at least one
    uint32_t material_count = 0;
    const MipTextureView* textures = nullptr;
    uint32_t texture_count = 0;
    LightSet lights;
    float epsilon = 1e-4f;
    float scene_diagonal = 1.0f;
    bool transparent_materials = false;
    const Vec3f* ambient = nullptr;  // per material, Material::ambient (nullptr: every one is zero)

    [[nodiscard]] RF_HDI SurfaceHit surface(const Ray& ray, const Hit& hit) const {
        return shading_surface(shading_triangles[hit.prim], ray, hit);
    }
    // The material of triangle `prim`, without interpolating anything.
    [[nodiscard]] RF_HDI uint32_t material_id(uint32_t prim) const { return shading_triangles[prim].material; }
    [[nodiscard]] RF_HDI const ShadingMaterial& material(uint32_t id) const {
        RF_ASSERT(material_count > 0, "a scene view without its fallback material");
        return materials[id < material_count ? id : 0];
    }
    // Material `id`'s ambient radiance (the Whitted integrator's term).
    [[nodiscard]] RF_HDI Vec3f material_ambient(uint32_t id) const {
        return ambient != nullptr && id < material_count ? ambient[id] : Vec3f(0.0f);
    }
    // nullptr for kNoTexture or an index out of range.
    [[nodiscard]] RF_HDI const MipTextureView* texture(int32_t id) const {
        return (id >= 0 && uint32_t(id) < texture_count) ? &textures[id] : nullptr;
    }
    // Whether any material is cut out or blended: shadow rays must then look
    // at what they hit instead of stopping at the first triangle.
    [[nodiscard]] RF_HDI bool has_transparent_materials() const { return transparent_materials; }
    [[nodiscard]] RF_HDI const LightSet& light_set() const { return lights; }
    [[nodiscard]] RF_HDI uint32_t light_count() const { return lights.light_count; }
    [[nodiscard]] RF_HDI const Light& light(uint32_t i) const { return lights.lights[i]; }
    [[nodiscard]] RF_HDI const EmitterTable& emitters() const { return lights.emitters; }
    [[nodiscard]] RF_HDI const Triangle* triangles() const { return lights.triangles; }
    // Material and texture coordinates at a point chosen on an emitter.
    [[nodiscard]] RF_HDI SurfaceHit emitter_surface(const AreaLightSample& s) const {
        Ray ray;
        Hit hit;
        emitter_ray_hit(s, ray, hit);
        return surface(ray, hit);
    }
    // Radiance arriving from the environment along unit direction `dir`.
    [[nodiscard]] RF_HDI Vec3f environment(Vec3f dir) const { return lights.environment.radiance(dir); }
    // How far secondary rays start off a surface: relative to the scene size.
    [[nodiscard]] RF_HDI float ray_epsilon() const { return epsilon; }
    // Length of the scene's bounding-box diagonal (1 for an empty scene).
    [[nodiscard]] RF_HDI float diagonal() const { return scene_diagonal; }
};

// The host tables a SceneView points into, built once from a scene: the
// shading materials, the shading records, the mip chains of the textures
// materials use and the light-sampling tables. `scene` and `geometry` must
// outlive it; the view stays valid when the tables are moved.
class SceneTables {
public:
    SceneTables(const Scene& scene, const SceneGeometry& geometry);
    SceneTables(const SceneTables&) = delete;
    SceneTables& operator=(const SceneTables&) = delete;

    [[nodiscard]] const SceneView& view() const { return view_; }
    // The arrays behind the view, for a backend that copies them (the CUDA backend).
    [[nodiscard]] std::span<const ShadingMaterial> materials() const { return materials_; }
    [[nodiscard]] std::span<const ShadingTriangle> shading_triangles() const { return shading_triangles_; }
    [[nodiscard]] std::span<const MipTextureView> textures() const { return textures_; }
    // Per material its ambient radiance; empty when every one is zero.
    [[nodiscard]] std::span<const Vec3f> ambient() const { return ambient_; }
    [[nodiscard]] uint32_t triangle_count() const { return triangle_count_; }

    // Memory of the mip chains and shading records built for this view.
    [[nodiscard]] size_t mip_bytes() const;
    [[nodiscard]] size_t shading_bytes() const { return shading_triangles_.size() * sizeof(ShadingTriangle); }

private:
    std::vector<ShadingMaterial> materials_;
    std::vector<ShadingTriangle> shading_triangles_;
    std::vector<Vec3f> ambient_;
    std::vector<std::unique_ptr<MipChain>> mip_chains_;  // parallel to scene.textures; null for unused textures
    std::vector<MipTextureView> textures_;
    std::unique_ptr<HostLightSet> lights_;  // on the heap: the view points into it
    uint32_t triangle_count_ = 0;
    SceneView view_;
};

}  // namespace rf
