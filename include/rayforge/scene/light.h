// Analytic lights and the environment. Emissive triangles (area lights) come
// from materials with emission and are listed by SceneGeometry.
#pragma once

#include <cstdint>

#include "rayforge/math/vec.h"

namespace rf {

enum class LightType : uint8_t { Point, Spot, Directional };

struct Light {
    LightType type = LightType::Point;
    Vec3f position{0, 0, 0};       // point, spot
    Vec3f direction{0, -1, 0};     // spot, directional: the direction light travels
    Vec3f color{1, 1, 1};          // linear RGB
    // Point/spot: intensity in candela (W/sr); directional: irradiance (W/m^2).
    float intensity = 1.0f;
    float inner_cone_radians = 0.0f;       // spot: full intensity inside
    float outer_cone_radians = 0.7853982f; // spot: zero outside (pi/4)
};

struct Environment {
    Vec3f color{0, 0, 0};          // constant radiance when texture == -1
    int32_t texture = -1;          // equirectangular HDR map (index into Scene::textures)
    float strength = 1.0f;         // multiplies color or texture
    float rotation_radians = 0.0f; // about +y
};

}  // namespace rf
