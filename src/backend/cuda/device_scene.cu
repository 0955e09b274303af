// DeviceScene (device_scene.h): a deep copy of a SceneTables' tables.
#include "backend/cuda/device_scene.h"

namespace rf::cuda {

template <class T>
const T* DeviceScene::copy(const T* host, size_t count, const std::string& what) {
    if (host == nullptr || count == 0) return nullptr;
    DeviceBuffer<unsigned char> buffer(what);
    buffer.upload(std::span<const unsigned char>(reinterpret_cast<const unsigned char*>(host), count * sizeof(T)));
    const T* device = reinterpret_cast<const T*>(buffer.data());
    buffers_.push_back(std::move(buffer));
    return device;
}

TextureView DeviceScene::copy_texture(const TextureView& host, const std::string& what) {
    TextureView view = host;
    if (!host.valid()) return view;
    const size_t values = size_t(host.width) * size_t(host.height) * size_t(host.channels);
    view.texels8 = copy(host.texels8, host.texels8 ? values : 0, what + " texels");
    view.texels_f = copy(host.texels_f, host.texels_f ? values : 0, what + " texels");
    if (host.decode8) {
        // The decode tables are shared (one per encoding): copy each once.
        const float* device = nullptr;
        for (const auto& [h, d] : decode_tables_)
            if (h == host.decode8) device = d;
        if (!device) {
            device = copy(host.decode8, 256, "texture decode table");
            decode_tables_.emplace_back(host.decode8, device);
        }
        view.decode8 = device;
    }
    return view;
}

DeviceScene::DeviceScene(const SceneTables& host) {
    SceneView& v = view_;
    v = host.view();  // the scalars; every pointer is replaced below
    const std::span<const ShadingTriangle> shading = host.shading_triangles();
    v.shading_triangles = copy(shading.data(), shading.size(), "shading records");
    // At least one material, as on the host (material() falls back to 0).
    const std::span<const ShadingMaterial> materials = host.materials();
    const ShadingMaterial fallback{};
    v.materials = materials.empty() ? copy(&fallback, 1, "materials") : copy(materials.data(), materials.size(), "materials");
    v.material_count = materials.empty() ? 1u : uint32_t(materials.size());
    const std::span<const Vec3f> ambient = host.ambient();
    v.ambient = ambient.empty() ? nullptr : copy(ambient.data(), ambient.size(), "material ambient");

    const std::span<const MipTextureView> textures = host.textures();
    std::vector<MipTextureView> device_textures(textures.begin(), textures.end());
    for (size_t t = 0; t < device_textures.size(); ++t)
        for (int level = 0; level < device_textures[t].level_count; ++level)
            device_textures[t].levels[level] = copy_texture(
                textures[t].levels[level], "texture " + std::to_string(t) + " level " + std::to_string(level));
    v.textures = copy(device_textures.data(), device_textures.size(), "texture views");
    v.texture_count = uint32_t(device_textures.size());

    const LightSet& lights = host.view().light_set();
    LightSet& d = v.lights;
    d.lights = copy(lights.lights, lights.light_count, "lights");
    d.emitters.triangles = copy(lights.emitters.triangles, lights.emitters.count, "emitter indices");
    d.emitters.cdf = copy(lights.emitters.cdf, lights.emitters.count, "emitter cdf");
    d.triangles = copy(lights.triangles, lights.triangles ? host.triangle_count() : 0, "light triangles");
    d.selection_cdf = copy(lights.selection_cdf, lights.selection_count, "light selection cdf");
    EnvironmentLight& env = d.environment;
    env.map = copy_texture(lights.environment.map, "environment map");
    if (lights.environment.has_distribution()) {
        const size_t w = size_t(lights.environment.width), h = size_t(lights.environment.height);
        env.marginal_cdf = copy(lights.environment.marginal_cdf, h + 1, "environment marginal cdf");
        env.conditional_cdf = copy(lights.environment.conditional_cdf, h * (w + 1), "environment conditional cdf");
    }
}

size_t DeviceScene::device_bytes() const {
    size_t bytes = 0;
    for (const auto& b : buffers_) bytes += b.bytes();
    return bytes;
}

}  // namespace rf::cuda
