#include "render/scene_view.h"

#include <cmath>

#include "backend/cpu/parallel.h"

namespace rf {
namespace {

std::vector<ShadingMaterial> shading_materials(const Scene& scene) {
    std::vector<ShadingMaterial> materials;
    materials.reserve(scene.materials.size() + 1);
    for (const Material& m : scene.materials) materials.push_back(ShadingMaterial::from(m));
    if (materials.empty()) materials.push_back(ShadingMaterial::from(Material{}));
    return materials;
}

// Textures some material samples with a footprint (the environment map is
// looked up at full resolution and needs no chain).
std::vector<uint8_t> textures_needing_mips(const Scene& scene) {
    std::vector<uint8_t> used(scene.textures.size(), 0);
    auto mark = [&](int32_t id) {
        if (id >= 0 && size_t(id) < used.size()) used[size_t(id)] = 1;
    };
    for (const Material& m : scene.materials) {
        mark(m.base_color_texture);
        mark(m.metallic_roughness_texture);
        mark(m.normal_texture);
        mark(m.emission_texture);
    }
    return used;
}

}  // namespace

HostSceneView::HostSceneView(const Scene& scene, const SceneGeometry& geometry)
    : scene_(&scene),
      geometry_(&geometry),
      materials_(shading_materials(scene)),
      shading_triangles_(build_shading_triangles(scene, geometry)),
      lights_(scene, geometry, materials_) {
    const std::vector<uint8_t> needs_mips = textures_needing_mips(scene);
    mip_chains_.resize(scene.textures.size());
    parallel::for_each_index(0, int(scene.textures.size()), [&](int i) {
        if (needs_mips[size_t(i)]) mip_chains_[size_t(i)] = std::make_unique<MipChain>(scene.textures[size_t(i)]);
    });
    textures_.reserve(scene.textures.size());
    for (size_t i = 0; i < scene.textures.size(); ++i)
        textures_.push_back(make_mip_view(scene.textures[i], mip_chains_[i].get()));

    for (const ShadingMaterial& m : materials_)
        if (m.alpha_mode != AlphaMode::Opaque) has_transparent_materials_ = true;

    if (!geometry.bounds.is_empty()) {
        float d = length(geometry.bounds.extent());
        if (std::isfinite(d) && d > 0.0f) diagonal_ = d;
    }
    // Large enough to clear float error at the hit point for scenes whose
    // coordinates are about the size of their extent, small against features.
    Vec3f far_corner = geometry.bounds.is_empty() ? Vec3f(0.0f) : max(abs(geometry.bounds.lo), abs(geometry.bounds.hi));
    ray_epsilon_ = std::fmax(1e-4f * diagonal_, 1e-5f * max_component(far_corner));
    if (!(ray_epsilon_ > 0.0f)) ray_epsilon_ = 1e-4f;
}

size_t HostSceneView::mip_bytes() const {
    size_t bytes = 0;
    for (const auto& chain : mip_chains_)
        if (chain) bytes += chain->memory_bytes();
    return bytes;
}

SurfaceHit HostSceneView::emitter_surface(const AreaLightSample& s) const {
    Ray ray;
    Hit hit;
    emitter_ray_hit(s, ray, hit);
    return surface(ray, hit);
}

}  // namespace rf
