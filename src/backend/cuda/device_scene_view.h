// The GPU's view of a scene for the integrators: the same member functions
// as HostSceneView (src/render/scene_view.h), over plain device pointers, so
// the integrators of src/render run on the device unchanged. Filling it
// (uploading materials, mip levels, shading records and light tables) is the
// CUDA renderer's job; the types here only fix what a device view holds.
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"
#include "render/light_set.h"
#include "render/material_eval.h"
#include "render/shading_triangles.h"
#include "render/texture_sampling.h"
#include "trace/bvh_traversal.h"

namespace rf::cuda {

struct DeviceSceneView {
    const ShadingTriangle* shading_triangles = nullptr;
    const ShadingMaterial* materials = nullptr;  // at least one
    uint32_t material_count = 0;
    const MipTextureView* textures = nullptr;    // level pointers into device memory
    uint32_t texture_count = 0;
    LightSet lights;                             // table pointers into device memory
    float epsilon = 1e-4f;
    float scene_diagonal = 1.0f;
    bool transparent_materials = false;

    RF_HD SurfaceHit surface(const Ray& ray, const Hit& hit) const {
        return shading_surface(shading_triangles[hit.prim], ray, hit);
    }
    RF_HD uint32_t material_id(uint32_t prim) const { return shading_triangles[prim].material; }
    RF_HD const ShadingMaterial& material(uint32_t id) const { return materials[id < material_count ? id : 0]; }
    RF_HD const MipTextureView* texture(int32_t id) const {
        return (id >= 0 && uint32_t(id) < texture_count) ? &textures[id] : nullptr;
    }
    RF_HD bool has_transparent_materials() const { return transparent_materials; }
    RF_HD const LightSet& light_set() const { return lights; }
    RF_HD uint32_t light_count() const { return lights.light_count; }
    RF_HD const Light& light(uint32_t i) const { return lights.lights[i]; }
    RF_HD const EmitterTable& emitters() const { return lights.emitters; }
    RF_HD const Triangle* triangles() const { return lights.triangles; }
    RF_HD SurfaceHit emitter_surface(const AreaLightSample& s) const {
        Ray ray;
        Hit hit;
        emitter_ray_hit(s, ray, hit);
        return surface(ray, hit);
    }
    RF_HD Vec3f environment(Vec3f dir) const { return lights.environment.radiance(dir); }
    RF_HD float ray_epsilon() const { return epsilon; }
    RF_HD float diagonal() const { return scene_diagonal; }
};

// The integrators' tracer over the canonical BVH on the device.
struct DeviceBvhTracer {
    BvhView bvh;
    RF_HD Hit intersect(const Ray& ray) const { return bvh_intersect(bvh, ray); }
    RF_HD bool occluded(const Ray& ray) const { return bvh_occluded(bvh, ray); }
};

}  // namespace rf::cuda
