// Small fixed-size vectors used by every stage (host and device).
#pragma once

#include <cmath>
#include <cstdint>

#include "rayforge/core/host_device.h"

namespace rf {

struct Vec2f {
    float x = 0, y = 0;
    RF_HDI float operator[](int i) const { return i == 0 ? x : y; }
};

struct Vec3f {
    float x = 0, y = 0, z = 0;
    Vec3f() = default;
    RF_HDI constexpr Vec3f(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
    RF_HDI explicit constexpr Vec3f(float s) : x(s), y(s), z(s) {}
    RF_HDI float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
    RF_HDI float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};

struct Vec4f {
    float x = 0, y = 0, z = 0, w = 0;
};

RF_HDI Vec2f operator+(Vec2f a, Vec2f b) { return {a.x + b.x, a.y + b.y}; }
RF_HDI Vec2f operator-(Vec2f a, Vec2f b) { return {a.x - b.x, a.y - b.y}; }
RF_HDI Vec2f operator*(Vec2f a, float s) { return {a.x * s, a.y * s}; }
RF_HDI Vec2f operator*(float s, Vec2f a) { return {a.x * s, a.y * s}; }

RF_HDI Vec3f operator+(Vec3f a, Vec3f b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
RF_HDI Vec3f operator-(Vec3f a, Vec3f b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
RF_HDI Vec3f operator-(Vec3f a) { return {-a.x, -a.y, -a.z}; }
RF_HDI Vec3f operator*(Vec3f a, Vec3f b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
RF_HDI Vec3f operator/(Vec3f a, Vec3f b) { return {a.x / b.x, a.y / b.y, a.z / b.z}; }
RF_HDI Vec3f operator*(Vec3f a, float s) { return {a.x * s, a.y * s, a.z * s}; }
RF_HDI Vec3f operator*(float s, Vec3f a) { return {a.x * s, a.y * s, a.z * s}; }
RF_HDI Vec3f operator/(Vec3f a, float s) { return a * (1.0f / s); }
RF_HDI Vec3f& operator+=(Vec3f& a, Vec3f b) { a = a + b; return a; }
RF_HDI Vec3f& operator-=(Vec3f& a, Vec3f b) { a = a - b; return a; }
RF_HDI Vec3f& operator*=(Vec3f& a, Vec3f b) { a = a * b; return a; }
RF_HDI Vec3f& operator*=(Vec3f& a, float s) { a = a * s; return a; }
RF_HDI bool operator==(Vec3f a, Vec3f b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

RF_HDI float dot(Vec3f a, Vec3f b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
RF_HDI Vec3f cross(Vec3f a, Vec3f b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
RF_HDI float length_squared(Vec3f a) { return dot(a, a); }
RF_HDI float length(Vec3f a) { return sqrtf(dot(a, a)); }
RF_HDI Vec3f normalize(Vec3f a) { return a * (1.0f / length(a)); }
RF_HDI Vec3f min(Vec3f a, Vec3f b) { return {fminf(a.x, b.x), fminf(a.y, b.y), fminf(a.z, b.z)}; }
RF_HDI Vec3f max(Vec3f a, Vec3f b) { return {fmaxf(a.x, b.x), fmaxf(a.y, b.y), fmaxf(a.z, b.z)}; }
RF_HDI Vec3f abs(Vec3f a) { return {fabsf(a.x), fabsf(a.y), fabsf(a.z)}; }
RF_HDI float min_component(Vec3f a) { return fminf(a.x, fminf(a.y, a.z)); }
RF_HDI float max_component(Vec3f a) { return fmaxf(a.x, fmaxf(a.y, a.z)); }
RF_HDI bool is_finite(float a) {
#if defined(__CUDA_ARCH__)
    return isfinite(a);
#else
    return std::isfinite(a);
#endif
}
RF_HDI bool is_finite(Vec3f a) { return is_finite(a.x) && is_finite(a.y) && is_finite(a.z); }
RF_HDI Vec3f lerp(Vec3f a, Vec3f b, float t) { return a * (1.0f - t) + b * t; }
// Reflection of the incoming direction d about the normal n.
RF_HDI Vec3f reflect(Vec3f d, Vec3f n) { return d - n * (2.0f * dot(d, n)); }

}  // namespace rf
