// Rays and hit records shared by every structure, traversal and backend.
#pragma once

#include <cstdint>

#include "rayforge/math/vec.h"

namespace rf {

inline constexpr uint32_t kInvalidId = 0xFFFFFFFFu;
inline constexpr float kInfinity = 3.402823466e+38f;  // FLT_MAX, usable on device

// A ray accepts hits with t in [tmin, tmax]. dir need not be normalised;
// t is measured in units of dir.
struct Ray {
    Vec3f org;
    float tmin = 0.0f;
    Vec3f dir;
    float tmax = kInfinity;
};

// Closest hit: t, barycentrics (u, v) of vertices 1 and 2, and the primitive
// (index into the flattened triangle array, see SceneGeometry). prim ==
// kInvalidId means a miss.
struct Hit {
    float t = kInfinity;
    float u = 0.0f;
    float v = 0.0f;
    uint32_t prim = kInvalidId;
    RF_HDI bool found() const { return prim != kInvalidId; }
};

}  // namespace rf
