#include "render/scene_view.h"

#include <algorithm>
#include <cmath>

#include "core/parallel.h"

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

// How far secondary rays start off a surface: large enough to clear float
// error at the hit point for scenes whose coordinates are about the size of
// their extent, small against features.
void set_scene_scale(const SceneGeometry& geometry, SceneView& view) {
    if (!geometry.bounds.is_empty()) {
        const float d = length(geometry.bounds.extent());
        if (std::isfinite(d) && d > 0.0f) view.scene_diagonal = d;
    }
    const Vec3f far_corner =
        geometry.bounds.is_empty() ? Vec3f(0.0f) : max(abs(geometry.bounds.lo), abs(geometry.bounds.hi));
    view.epsilon = std::fmax(1e-4f * view.scene_diagonal, 1e-5f * max_component(far_corner));
    if (!(view.epsilon > 0.0f)) view.epsilon = 1e-4f;
}

}  // namespace

SceneTables::SceneTables(const Scene& scene, const SceneGeometry& geometry)
    : materials_(shading_materials(scene)),
      shading_triangles_(build_shading_triangles(scene, geometry)),
      triangle_count_(uint32_t(geometry.triangles.size())) {
    const std::vector<uint8_t> needs_mips = textures_needing_mips(scene);
    mip_chains_.resize(scene.textures.size());
    parallel::for_each_index(0, int(scene.textures.size()), [&](int i) {
        if (needs_mips[size_t(i)]) mip_chains_[size_t(i)] = std::make_unique<MipChain>(scene.textures[size_t(i)]);
    });
    textures_.reserve(scene.textures.size());
    for (size_t i = 0; i < scene.textures.size(); ++i)
        textures_.push_back(make_mip_view(scene.textures[i], mip_chains_[i].get()));
    lights_ = std::make_unique<HostLightSet>(scene, geometry, materials_, textures_);  // weighs textured emitters

    SceneView& v = view_;
    v.shading_triangles = shading_triangles_.data();
    v.materials = materials_.data();
    v.material_count = uint32_t(materials_.size());
    v.textures = textures_.data();
    v.texture_count = uint32_t(textures_.size());
    v.lights = lights_->view();
    for (const ShadingMaterial& m : materials_)
        if (m.alpha_mode != AlphaMode::Opaque) v.transparent_materials = true;
    const bool any_ambient = std::any_of(scene.materials.begin(), scene.materials.end(),
                                         [](const Material& m) { return max_component(m.ambient) > 0.0f; });
    if (any_ambient && scene.materials.size() == materials_.size()) {
        for (const Material& m : scene.materials) ambient_.push_back(max(m.ambient, Vec3f(0.0f)));
        v.ambient = ambient_.data();
    }
    set_scene_scale(geometry, v);
}

size_t SceneTables::mip_bytes() const {
    size_t bytes = 0;
    for (const auto& chain : mip_chains_)
        if (chain) bytes += chain->memory_bytes();
    return bytes;
}

}  // namespace rf
