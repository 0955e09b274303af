#include "io/phong_material.h"

#include <algorithm>
#include <cmath>

namespace rf::io {

float phong_roughness(float exponent) {
    const float n = std::isfinite(exponent) ? std::max(0.0f, exponent) : 0.0f;
    return std::clamp(std::sqrt(std::sqrt(2.0f / (n + 2.0f))), 0.0f, 1.0f);
}

void set_phong_specular(Vec3f ks, float exponent, Material& m) {
    const float strength = max_component(ks);
    if (!(strength >= kNoSpecularBelow)) {  // also NaN
        m.specular = 0.0f;
        m.specular_color = Vec3f(1.0f);
        m.roughness = 1.0f;  // irrelevant without a layer; the glTF default
        return;
    }
    m.specular = std::min(strength, 1.0f);
    m.specular_color = max(ks, Vec3f(0.0f)) / strength;
    m.roughness = phong_roughness(exponent);
}

bool phong_mirror(Vec3f kd, Vec3f ks) {
    return max_component(ks) >= 0.5f && max_component(ks) >= max_component(kd);
}

void set_phong_mirror(Vec3f ks, float exponent, Material& m) {
    m.metallic = 1.0f;
    m.base_color = min(max(ks, Vec3f(0.0f)), Vec3f(1.0f));
    m.specular = 1.0f;
    m.specular_color = Vec3f(1.0f);
    m.roughness = phong_roughness(exponent);
}

}  // namespace rf::io
