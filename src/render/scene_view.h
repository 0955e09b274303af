// The CPU's view of a scene for the integrators: materials flattened to
// ShadingMaterial, textures with their mip chains as MipTextureView, every
// emitter as one LightSet, and shading attributes through rf::surface_at.
// The integrators are templates over the view and the tracer, so a GPU
// backend supplies its own view and tracer with the same member functions.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "render/area_lights.h"
#include "render/light_set.h"
#include "render/material_eval.h"
#include "render/shading_triangles.h"
#include "render/texture_mip.h"
#include "render/texture_sampling.h"

namespace rf {

class HostSceneView {
public:
    // `scene` and `geometry` must outlive the view. Builds the mip chains of
    // the textures materials use and the light-sampling tables.
    HostSceneView(const Scene& scene, const SceneGeometry& geometry);

    [[nodiscard]] SurfaceHit surface(const Ray& ray, const Hit& hit) const {
        return shading_surface(shading_triangles_[hit.prim], ray, hit);
    }
    // The material of triangle `prim`, without interpolating anything.
    [[nodiscard]] uint32_t material_id(uint32_t prim) const { return shading_triangles_[prim].material; }
    [[nodiscard]] const ShadingMaterial& material(uint32_t id) const {
        return materials_[id < materials_.size() ? id : 0];
    }
    // nullptr for kNoTexture or an index out of range.
    [[nodiscard]] const MipTextureView* texture(int32_t id) const {
        return (id >= 0 && size_t(id) < textures_.size()) ? &textures_[size_t(id)] : nullptr;
    }
    // Whether any material is cut out or blended: shadow rays must then look
    // at what they hit instead of stopping at the first triangle.
    [[nodiscard]] bool has_transparent_materials() const { return has_transparent_materials_; }

    [[nodiscard]] const LightSet& light_set() const { return lights_.view(); }
    [[nodiscard]] uint32_t light_count() const { return uint32_t(scene_->lights.size()); }
    [[nodiscard]] const Light& light(uint32_t i) const { return scene_->lights[i]; }
    [[nodiscard]] const EmitterTable& emitters() const { return lights_.view().emitters; }
    [[nodiscard]] const Triangle* triangles() const { return geometry_->triangles.data(); }
    // Material and texture coordinates at a point chosen on an emitter.
    [[nodiscard]] SurfaceHit emitter_surface(const AreaLightSample& s) const;

    // Radiance arriving from the environment along unit direction `dir`.
    [[nodiscard]] Vec3f environment(Vec3f dir) const { return lights_.view().environment.radiance(dir); }

    // Length of the scene's bounding-box diagonal (1 for an empty scene).
    [[nodiscard]] float diagonal() const { return diagonal_; }
    // How far secondary rays start off a surface: relative to the scene size.
    [[nodiscard]] float ray_epsilon() const { return ray_epsilon_; }
    // The flat tables behind the view, for a backend that copies them (the CUDA backend).
    [[nodiscard]] std::span<const ShadingMaterial> materials() const { return materials_; }
    [[nodiscard]] std::span<const ShadingTriangle> shading_triangles() const { return shading_triangles_; }
    [[nodiscard]] std::span<const MipTextureView> textures() const { return textures_; }
    [[nodiscard]] uint32_t triangle_count() const { return uint32_t(geometry_->triangles.size()); }

    // Memory of the mip chains and shading records built for this view.
    [[nodiscard]] size_t mip_bytes() const;
    [[nodiscard]] size_t shading_bytes() const { return shading_triangles_.size() * sizeof(ShadingTriangle); }

private:
    const Scene* scene_;
    const SceneGeometry* geometry_;
    std::vector<ShadingMaterial> materials_;
    std::vector<ShadingTriangle> shading_triangles_;
    std::vector<std::unique_ptr<MipChain>> mip_chains_;  // parallel to scene.textures; null for unused textures
    std::vector<MipTextureView> textures_;
    HostLightSet lights_;
    bool has_transparent_materials_ = false;
    float diagonal_ = 1.0f;
    float ray_epsilon_ = 1e-4f;
};

// The tracer the integrators see on the CPU: an rf::Accel, counting the
// queries it answers and optionally logging them (counters and log are the
// caller's, one set per task).
struct AccelTracer {
    const Accel* accel;
    uint64_t* closest_count = nullptr;
    uint64_t* shadow_count = nullptr;
    std::vector<TracedRay>* log = nullptr;
    [[nodiscard]] Hit intersect(const Ray& ray) const {
        if (closest_count) ++*closest_count;
        if (log) log->push_back({ray, false});
        return accel->intersect(ray);
    }
    [[nodiscard]] bool occluded(const Ray& ray) const {
        if (shadow_count) ++*shadow_count;
        if (log) log->push_back({ray, true});
        return accel->occluded(ray);
    }
};

}  // namespace rf
