// Material evaluation shared by both backends: a device-friendly copy of
// rf::Material (no strings) and its value at a surface point, with textures
// applied (glTF 2.0 metallic-roughness, tangent-space normal maps). `View` is
// any scene view whose `texture(int32_t)` returns `const MipTextureView*` (or
// `const TextureView*`, sampled without mip-mapping), nullptr when absent.
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/material.h"
#include "render/texture_lod.h"
#include "render/texture_sampling.h"

namespace rf {

struct ShadingMaterial {
    Vec3f base_color{0.8f, 0.8f, 0.8f};
    float alpha = 1.0f;
    int32_t base_color_texture = kNoTexture;
    float metallic = 0.0f;
    float roughness = 1.0f;
    int32_t metallic_roughness_texture = kNoTexture;
    int32_t normal_texture = kNoTexture;
    float normal_scale = 1.0f;
    Vec3f emission{0.0f, 0.0f, 0.0f};   // factor * strength
    int32_t emission_texture = kNoTexture;
    float transmission = 0.0f;
    float ior = 1.5f;
    float specular = 1.0f;
    Vec3f specular_color{1.0f, 1.0f, 1.0f};
    AlphaMode alpha_mode = AlphaMode::Opaque;
    float alpha_cutoff = 0.5f;
    bool two_sided_emission = false;

    static ShadingMaterial from(const Material& m) {
        ShadingMaterial s;
        s.base_color = m.base_color;
        s.alpha = m.alpha;
        s.base_color_texture = m.base_color_texture;
        s.metallic = m.metallic;
        s.roughness = m.roughness;
        s.metallic_roughness_texture = m.metallic_roughness_texture;
        s.normal_texture = m.normal_texture;
        s.normal_scale = m.normal_scale;
        s.emission = m.is_emissive() ? m.emitted_radiance() : Vec3f(0.0f);
        s.emission_texture = m.emission_texture;
        s.transmission = m.transmission;
        s.ior = m.ior;
        s.specular = m.specular;
        s.specular_color = m.specular_color;
        s.alpha_mode = m.alpha_mode;
        s.alpha_cutoff = m.alpha_cutoff;
        s.two_sided_emission = m.two_sided_emission;
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
    float specular = 1.0f;      // in [0, 1]
    Vec3f specular_color{1.0f};  // in [0, 1]
};

RF_HDI float saturate(float x) { return fminf(fmaxf(x, 0.0f), 1.0f); }

// A lookup at `lod_base` (see texture_lod.h): a plain view has no coarser
// levels and is sampled bilinearly; a mip view picks its own level.
RF_HDI Vec4f sample_texture_at(const TextureView& t, Vec2f uv, float /*lod_base*/) {
    return sample_texture(t, uv);
}
RF_HDI Vec4f sample_texture_at(const MipTextureView& t, Vec2f uv, float lod_base) {
    return sample_texture(t, uv, texture_level(t, lod_base));
}

// The material at texture coordinate `uv`; `lod_base` is the hit's
// texture-independent level of detail, -inf (the default) for the finest level.
template <class View>
RF_HD MaterialSample evaluate_material(const View& view, const ShadingMaterial& m, Vec2f uv,
                                       float lod_base = -kInfinity) {
    MaterialSample s;
    s.base_color = m.base_color;
    s.alpha = m.alpha;
    if (const auto* t = view.texture(m.base_color_texture)) {
        Vec4f c = sample_texture_at(*t, uv, lod_base);
        s.base_color = s.base_color * Vec3f(c.x, c.y, c.z);
        s.alpha *= c.w;
    }
    s.metallic = m.metallic;
    s.roughness = m.roughness;
    if (const auto* t = view.texture(m.metallic_roughness_texture)) {
        Vec4f c = sample_texture_at(*t, uv, lod_base);  // glTF: G = roughness, B = metallic
        s.roughness *= c.y;
        s.metallic *= c.z;
    }
    s.emission = m.emission;
    if (const auto* t = view.texture(m.emission_texture)) {
        Vec4f c = sample_texture_at(*t, uv, lod_base);
        s.emission = s.emission * Vec3f(c.x, c.y, c.z);
    }
    s.base_color = max(s.base_color, Vec3f(0.0f));
    s.alpha = saturate(s.alpha);
    s.metallic = saturate(s.metallic);
    s.roughness = saturate(s.roughness);
    s.emission = max(s.emission, Vec3f(0.0f));
    s.transmission = saturate(m.transmission);
    s.ior = m.ior >= 1.0f ? m.ior : 1.0f;
    s.specular = saturate(m.specular);
    s.specular_color = min(max(m.specular_color, Vec3f(0.0f)), Vec3f(1.0f));
    return s;
}

// The tangent-space normal from the material's normal map (glTF:
// n = normalize((2 rgb - 1) * (scale, scale, 1))), +z when there is none or
// the texel decodes to a zero vector. Filtered texels are averaged vectors,
// shorter than 1; normalising restores a unit normal.
template <class View>
RF_HD Vec3f sample_normal_map(const View& view, const ShadingMaterial& m, Vec2f uv,
                              float lod_base = -kInfinity) {
    const auto* t = view.texture(m.normal_texture);
    if (!t) return {0.0f, 0.0f, 1.0f};
    Vec4f c = sample_texture_at(*t, uv, lod_base);
    Vec3f n{(2.0f * c.x - 1.0f) * m.normal_scale, (2.0f * c.y - 1.0f) * m.normal_scale,
            2.0f * c.z - 1.0f};
    float len2 = dot(n, n);
    if (!(len2 > 1e-12f) || !(len2 <= 3.402823466e+38f)) return {0.0f, 0.0f, 1.0f};
    return n * (1.0f / sqrtf(len2));
}

}  // namespace rf
