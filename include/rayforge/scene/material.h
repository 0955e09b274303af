// Materials in the glTF 2.0 metallic-roughness model (with the
// emissive_strength, transmission, ior and specular extensions).
#pragma once

#include <cstdint>
#include <string>

#include "rayforge/math/vec.h"

namespace rf {

inline constexpr int32_t kNoTexture = -1;

enum class AlphaMode : uint8_t { Opaque, Mask, Blend };

struct Material {
    std::string name;
    Vec3f base_color{0.8f, 0.8f, 0.8f};   // linear RGB factor
    float alpha = 1.0f;                    // base color alpha factor (opacity)
    int32_t base_color_texture = kNoTexture;  // index into Scene::textures
    float metallic = 0.0f;
    float roughness = 1.0f;
    int32_t metallic_roughness_texture = kNoTexture;  // glTF: G = roughness, B = metallic
    int32_t normal_texture = kNoTexture;
    float normal_scale = 1.0f;
    Vec3f emission{0.0f, 0.0f, 0.0f};      // linear RGB emissive factor
    float emission_strength = 1.0f;        // KHR_materials_emissive_strength
    int32_t emission_texture = kNoTexture;
    float transmission = 0.0f;             // KHR_materials_transmission
    float ior = 1.5f;                      // KHR_materials_ior
    // KHR_materials_specular: strength and colour of the dielectric specular
    // layer; specular = 0 leaves a purely Lambertian (or transmissive) base.
    float specular = 1.0f;
    Vec3f specular_color{1.0f, 1.0f, 1.0f};
    AlphaMode alpha_mode = AlphaMode::Opaque;
    float alpha_cutoff = 0.5f;
    // Emission from both faces; otherwise only the front face (counter-
    // clockwise winding seen from outside) emits. glTF: doubleSided.
    bool two_sided_emission = false;
    // Whitted's ambient term (Whitted 1980: k_a * I_a): radiance a surface
    // reflects whatever the lights, times its base-color texture where it
    // has one. BART's AFF scenes set it (am * the material's ambient color);
    // only the Whitted integrator adds it, the physically based ones do not.
    Vec3f ambient{0.0f, 0.0f, 0.0f};

    [[nodiscard]] Vec3f emitted_radiance() const { return emission * emission_strength; }
    [[nodiscard]] bool is_emissive() const {
        return (emission.x > 0 || emission.y > 0 || emission.z > 0) && emission_strength > 0;
    }
};

}  // namespace rf
