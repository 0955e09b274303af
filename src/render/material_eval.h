// Material evaluation shared by both backends: a device-friendly copy of
// rf::Material (no strings) and its value at a surface point, with textures
// applied. `View` is any scene view with `const TextureView* texture(int32_t)`.
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/material.h"
#include "render/texture_sampling.h"

namespace rf {

struct ShadingMaterial {
    Vec3f base_color{0.8f, 0.8f, 0.8f};
    float alpha = 1.0f;
    int32_t base_color_texture = kNoTexture;
    float metallic = 0.0f;
    float roughness = 1.0f;
    int32_t metallic_roughness_texture = kNoTexture;
    Vec3f emission{0.0f, 0.0f, 0.0f};   // factor * strength
    int32_t emission_texture = kNoTexture;
    float transmission = 0.0f;
    float ior = 1.5f;
    AlphaMode alpha_mode = AlphaMode::Opaque;
    float alpha_cutoff = 0.5f;
    bool double_sided = true;

    static ShadingMaterial from(const Material& m) {
        ShadingMaterial s;
        s.base_color = m.base_color;
        s.alpha = m.alpha;
        s.base_color_texture = m.base_color_texture;
        s.metallic = m.metallic;
        s.roughness = m.roughness;
        s.metallic_roughness_texture = m.metallic_roughness_texture;
        s.emission = m.is_emissive() ? m.emitted_radiance() : Vec3f(0.0f);
        s.emission_texture = m.emission_texture;
        s.transmission = m.transmission;
        s.ior = m.ior;
        s.alpha_mode = m.alpha_mode;
        s.alpha_cutoff = m.alpha_cutoff;
        s.double_sided = m.double_sided;
        return s;
    }
};

// The material's parameters at one surface point, textures applied and
// clamped to their meaningful ranges.
struct MaterialSample {
    Vec3f base_color;
    float alpha = 1.0f;
    float metallic = 0.0f;
    float roughness = 1.0f;
    Vec3f emission;
    float transmission = 0.0f;
    float ior = 1.5f;
};

RF_HDI float saturate(float x) { return fminf(fmaxf(x, 0.0f), 1.0f); }

template <class View>
RF_HD MaterialSample evaluate_material(const View& view, const ShadingMaterial& m, Vec2f uv) {
    MaterialSample s;
    s.base_color = m.base_color;
    s.alpha = m.alpha;
    if (const TextureView* t = view.texture(m.base_color_texture)) {
        Vec4f c = sample_texture(*t, uv);
        s.base_color = s.base_color * Vec3f(c.x, c.y, c.z);
        s.alpha *= c.w;
    }
    s.metallic = m.metallic;
    s.roughness = m.roughness;
    if (const TextureView* t = view.texture(m.metallic_roughness_texture)) {
        Vec4f c = sample_texture(*t, uv);  // glTF: G = roughness, B = metallic
        s.roughness *= c.y;
        s.metallic *= c.z;
    }
    s.emission = m.emission;
    if (const TextureView* t = view.texture(m.emission_texture)) {
        Vec4f c = sample_texture(*t, uv);
        s.emission = s.emission * Vec3f(c.x, c.y, c.z);
    }
    s.base_color = max(s.base_color, Vec3f(0.0f));
    s.alpha = saturate(s.alpha);
    s.metallic = saturate(s.metallic);
    s.roughness = saturate(s.roughness);
    s.emission = max(s.emission, Vec3f(0.0f));
    s.transmission = saturate(m.transmission);
    s.ior = m.ior >= 1.0f ? m.ior : 1.0f;
    return s;
}

}  // namespace rf
