// Sampling routines shared by the integrators on both backends.
#pragma once

#include <cmath>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"

namespace rf {

inline constexpr float kPi = 3.14159265358979323846f;
inline constexpr float kInvPi = 0.31830988618379067154f;

// Orthonormal basis (t, b, n) around a unit normal n, branchless and free of
// the singularity of the classic construction: Duff, Burgess, Christensen,
// Hery, Kensler, Liani, Villemin 2017, "Building an Orthonormal Basis,
// Revisited" (JCGT 6(1)).
struct Frame {
    Vec3f t, b, n;

    RF_HDI static Frame from_normal(Vec3f n) {
        float sign = copysignf(1.0f, n.z);
        float a = -1.0f / (sign + n.z);
        float b = n.x * n.y * a;
        return {Vec3f(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x),
                Vec3f(b, sign + n.y * n.y * a, -n.y), n};
    }
    // Local (x, y, z) with z along n -> world.
    RF_HDI Vec3f to_world(Vec3f v) const { return t * v.x + b * v.y + n * v.z; }
};

// Cosine-weighted direction on the hemisphere around +z (Malley's method:
// uniform disk point lifted to the hemisphere); pdf = cos(theta) / pi.
RF_HDI Vec3f sample_cosine_hemisphere(Vec2f u) {
    float r = sqrtf(u.x);
    float phi = 2.0f * kPi * u.y;
    return {r * cosf(phi), r * sinf(phi), sqrtf(fmaxf(0.0f, 1.0f - u.x))};
}

// Uniform point on a triangle as barycentrics (b1, b2) of vertices 1 and 2
// (Shirley & Chiu's square-root mapping); pdf = 1 / area.
RF_HDI Vec2f sample_uniform_triangle(Vec2f u) {
    float s = sqrtf(u.x);
    return {s * (1.0f - u.y), s * u.y};
}

}  // namespace rf
