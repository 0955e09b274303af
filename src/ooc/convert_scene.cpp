#include "ooc/convert_scene.h"

#include <map>

#include "rayforge/core/error.h"

namespace rf::pack {

namespace {

// Textures the materials use, written once each; returns scene index -> paged index.
std::map<int32_t, int32_t> write_textures(const Scene& scene, PackWriter& writer) {
    std::map<int32_t, int32_t> paged;
    for (const Material& m : scene.materials)
        for (int32_t id : {m.base_color_texture, m.metallic_roughness_texture, m.normal_texture, m.emission_texture})
            if (id >= 0 && size_t(id) < scene.textures.size() && !paged.count(id))
                paged[id] = int32_t(writer.add_texture(scene.textures[size_t(id)]));
    return paged;
}

void write_materials(const Scene& scene, const std::map<int32_t, int32_t>& textures, PackWriter& writer,
                     std::vector<std::string>& notes) {
    const auto remap = [&](int32_t id) {
        const auto it = textures.find(id);
        return it == textures.end() ? kNoTexture : it->second;
    };
    bool made_opaque = false, normal_maps = false;
    for (const Material& m : scene.materials) {
        ShadingMaterial s = ShadingMaterial::from(m);
        s.base_color_texture = remap(m.base_color_texture);
        s.metallic_roughness_texture = remap(m.metallic_roughness_texture);
        s.normal_texture = remap(m.normal_texture);
        s.emission_texture = remap(m.emission_texture);
        if (s.alpha_mode != AlphaMode::Opaque || s.alpha < 1.0f) made_opaque = true;
        s.alpha_mode = AlphaMode::Opaque;
        s.alpha = 1.0f;
        normal_maps |= s.normal_texture != kNoTexture;
        writer.add_material(s);
    }
    if (made_opaque) notes.push_back("cut-out and blended materials were made opaque (paged scenes trace opaque surfaces)");
    if (normal_maps) notes.push_back("normal maps are stored but not applied (no tangent frames in paged records)");
}

}  // namespace

void write_scene_look(const Scene& scene, const Camera& camera, PackWriter& writer, std::vector<std::string>& notes) {
    const std::map<int32_t, int32_t> textures = write_textures(scene, writer);
    write_materials(scene, textures, writer, notes);
    for (const Light& light : scene.lights) writer.add_light(light);
    const Environment& env = scene.environment;
    const bool env_emits = (env.texture >= 0 || max_component(env.color) > 0.0f) && env.strength > 0.0f;
    if (scene.lights.empty() && !env_emits) {
        // As `render` does for an unlit in-core scene (paged files sample
        // no emitting triangles): lights a white diffuse surface at the
        // target distance to about 1.
        Light headlight;
        headlight.position = camera.eye;
        const float distance = length(camera.target - camera.eye);
        headlight.intensity = 3.14159265f * distance * distance;
        writer.add_light(headlight);
        notes.push_back("the scene has no light: a headlight at the default camera was added");
    }
    writer.set_camera(camera);
    writer.set_environment(scene.environment);
    if (scene.environment.texture >= 0)
        notes.push_back("the environment map was replaced by its constant colour times strength");
}

ConvertResult convert_scene(const Scene& scene, const std::string& path, const PackWriterOptions& options,
                            const ProgressCallback& progress) {
    ConvertResult result;
    PackWriter writer(path, options);
    write_scene_look(scene, scene.camera_or_default(), writer, result.notes);
    if (progress) progress(0.0);
    size_t done = 0;
    const size_t total = std::max<size_t>(1, scene.triangle_count());
    if (scene.animated())
        result.notes.push_back("the scene is animated; a paged file holds it as it is at time " +
                               std::to_string(scene.time) + " s");
    // A mesh placed by two or more visible instances is written once, in its
    // own space, and placed by instances (the seed's clones); a mesh placed
    // once is written in world space.
    std::vector<uint32_t> uses(scene.meshes.size(), 0);
    if (!options.flatten_instances)
        for (const Instance& instance : scene.instances) uses[instance.mesh] += instance.visible ? 1 : 0;
    constexpr uint32_t kNotWritten = 0xFFFFFFFFu;
    std::vector<uint32_t> object_of(scene.meshes.size(), kNotWritten);
    for (const Instance& instance : scene.instances) {
        const Mesh& mesh = scene.meshes[instance.mesh];
        done += mesh.triangle_count();
        if (!instance.visible) continue;  // hidden at this time: not in the file
        const bool instanced = uses[instance.mesh] > 1;
        if (instanced && object_of[instance.mesh] != kNotWritten) {
            writer.add_instance(object_of[instance.mesh], instance.transform);
            continue;
        }
        const Affine3f to_file = instanced ? Affine3f::identity() : instance.transform;
        std::vector<Vec3f> positions(mesh.positions.size());
        for (size_t i = 0; i < positions.size(); ++i) positions[i] = to_file.transform_point(mesh.positions[i]);
        const Affine3f normal_matrix = to_file.normal_matrix();
        std::vector<ShadingTriangle> shading(mesh.triangle_count());
        for (size_t t = 0; t < shading.size(); ++t) {
            const uint32_t* idx = &mesh.indices[3 * t];
            const Triangle tri{positions[idx[0]], positions[idx[1]], positions[idx[2]]};
            const uint32_t material = t < mesh.material_ids.size() ? mesh.material_ids[t] : 0;
            shading[t] = make_shading_triangle(mesh.normals, mesh.uvs, normal_matrix, tri, idx, material);
        }
        if (instanced) {
            object_of[instance.mesh] = writer.add_instanced_object({positions, mesh.indices, shading});
            writer.add_instance(object_of[instance.mesh], instance.transform);
        } else {
            writer.add_object({positions, mesh.indices, shading});
        }
        if (progress) progress(0.9 * double(done) / double(total));
    }
    result.summary = writer.finish([&](double f) {
        if (progress) progress(0.9 + 0.1 * f);
    });
    return result;
}

}  // namespace rf::pack
