#include "rayforge/scene/scene.h"

#include <cmath>
#include <string>

#include "rayforge/core/error.h"
#include "scene/animation_eval.h"

namespace rf {

size_t Scene::triangle_count() const {
    size_t n = 0;
    for (const Instance& inst : instances) n += meshes[inst.mesh].triangle_count();
    return n;
}

size_t Scene::vertex_count() const {
    size_t n = 0;
    for (const Instance& inst : instances) n += meshes[inst.mesh].vertex_count();
    return n;
}

Box3f Scene::bounds() const {
    Box3f b;
    for (const Instance& inst : instances)  // hidden instances are collapsed to a point: not part of the view
        if (inst.visible) b.extend(inst.transform.transform_box(meshes[inst.mesh].bounds()));
    return b;
}

size_t Scene::memory_bytes() const {
    size_t n = 0;
    for (const Mesh& m : meshes) n += m.memory_bytes();
    for (const Texture& t : textures) n += t.memory_bytes();
    n += instances.size() * sizeof(Instance) + materials.size() * sizeof(Material) + lights.size() * sizeof(Light);
    return n;
}

Camera Scene::camera_or_default() const { return camera ? *camera : framing(bounds()); }

Camera Scene::framing(const Box3f& b) {
    Camera cam;
    if (b.is_empty()) return cam;
    // Frame the bounding sphere from the +z side with the default 45° field of view.
    Vec3f center = b.center();
    float radius = 0.5f * length(b.extent());
    if (!(radius > 0.0f)) radius = 1.0f;
    float distance = radius / std::tan(0.5f * cam.vfov_degrees * 3.14159265f / 180.0f) * 1.1f;
    cam.target = center;
    cam.eye = center + Vec3f{0, 0, distance};
    return cam;
}

void Scene::validate_materials() const {
    for (const Mesh& mesh : meshes)
        for (uint32_t id : mesh.material_ids)
            if (id >= materials.size())
                throw Error("mesh '" + mesh.name + "': material " + std::to_string(id) + " of " +
                            std::to_string(materials.size()));
    auto check_texture = [&](int32_t t, const std::string& what, const std::string& material) {
        if (t != kNoTexture && (t < 0 || size_t(t) >= textures.size()))
            throw Error("material '" + material + "': " + what + " texture " + std::to_string(t) + " of " +
                        std::to_string(textures.size()));
    };
    for (const Material& m : materials) {
        check_texture(m.base_color_texture, "base color", m.name);
        check_texture(m.metallic_roughness_texture, "metallic-roughness", m.name);
        check_texture(m.normal_texture, "normal", m.name);
        check_texture(m.emission_texture, "emission", m.name);
    }
    if (environment.texture != -1 && (environment.texture < 0 || size_t(environment.texture) >= textures.size()))
        throw Error("environment texture " + std::to_string(environment.texture) + " of " + std::to_string(textures.size()));
}

void Scene::finalize() {
    if (materials.empty()) {
        Material m;
        m.name = "default";
        materials.push_back(m);
    }
    if (instances.empty())
        for (uint32_t i = 0; i < meshes.size(); ++i) instances.push_back({i, Affine3f::identity()});
    for (Mesh& mesh : meshes) {
        if (mesh.material_ids.empty()) mesh.material_ids.assign(mesh.triangle_count(), 0);
        mesh.validate();
    }
    for (const Instance& inst : instances)
        if (inst.mesh >= meshes.size())
            throw Error("instance references mesh " + std::to_string(inst.mesh) + " of " + std::to_string(meshes.size()));
    validate_materials();
    finalize_animation(*this);  // src/scene/animation.cpp: validation, rest positions and camera
}

}  // namespace rf
