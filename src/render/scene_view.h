// The CPU's view of a scene for the integrators: materials flattened to
// ShadingMaterial, textures to TextureView, the emitter table, the
// environment, and shading attributes through rf::surface_at. The
// integrators are templates over the view and the tracer, so a GPU backend
// supplies its own view and tracer with the same member functions.
#pragma once

#include <cstdint>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "render/area_lights.h"
#include "render/material_eval.h"
#include "render/texture_sampling.h"

namespace rf {

class HostSceneView {
public:
    // `scene` and `geometry` must outlive the view.
    HostSceneView(const Scene& scene, const SceneGeometry& geometry);

    [[nodiscard]] SurfaceHit surface(const Ray& ray, const Hit& hit) const {
        return surface_at(*scene_, *geometry_, ray, hit);
    }
    [[nodiscard]] const ShadingMaterial& material(uint32_t id) const {
        return materials_[id < materials_.size() ? id : 0];
    }
    // nullptr for kNoTexture or an index out of range.
    [[nodiscard]] const TextureView* texture(int32_t id) const {
        return (id >= 0 && size_t(id) < textures_.size()) ? &textures_[size_t(id)] : nullptr;
    }
    [[nodiscard]] uint32_t light_count() const { return uint32_t(scene_->lights.size()); }
    [[nodiscard]] const Light& light(uint32_t i) const { return scene_->lights[i]; }

    [[nodiscard]] const EmitterTable& emitters() const { return emitter_table_; }
    [[nodiscard]] const Triangle* triangles() const { return geometry_->triangles.data(); }
    // Material and texture coordinates at a point chosen on an emitter.
    [[nodiscard]] SurfaceHit emitter_surface(const AreaLightSample& s) const;

    // Radiance arriving from the environment along unit direction `dir`.
    [[nodiscard]] Vec3f environment(Vec3f dir) const;

    // Length of the scene's bounding-box diagonal (1 for an empty scene).
    [[nodiscard]] float diagonal() const { return diagonal_; }
    // How far secondary rays start off a surface: relative to the scene size.
    [[nodiscard]] float ray_epsilon() const { return ray_epsilon_; }

private:
    const Scene* scene_;
    const SceneGeometry* geometry_;
    std::vector<ShadingMaterial> materials_;
    std::vector<TextureView> textures_;
    std::vector<uint32_t> emitter_triangles_;
    std::vector<float> emitter_cdf_;
    EmitterTable emitter_table_;
    TextureView environment_texture_;
    float diagonal_ = 1.0f;
    float ray_epsilon_ = 1e-4f;
};

// The tracer the integrators see on the CPU: an rf::Accel.
struct AccelTracer {
    const Accel* accel;
    [[nodiscard]] Hit intersect(const Ray& ray) const { return accel->intersect(ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const { return accel->occluded(ray); }
};

}  // namespace rf
