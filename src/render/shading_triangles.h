// What shading needs of a hit triangle, packed into one 64-byte cache line
// per triangle: its unit geometric normal, material, vertex normals
// (octahedral-encoded, Meyer, Eisemann, Hoppe et al. 2010, "On Floating-Point
// Normal Vectors", 2x16 bits, error below 1e-4 rad) and uvs, all in world
// space. Without it, interpolating a hit's attributes walks instance -> mesh
// -> index buffer -> three normals -> three uvs, a chain of dependent cache
// misses that cost more than the rest of the shading (the dissertation's
// renderer pages such attributes per object for the same reason, ch. 6.4).
// Device-friendly: plain data, RF_HD decoding.
#pragma once

#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

struct alignas(64) ShadingTriangle {
    Vec3f geometric_normal;   // unit, as wound ((0,0,1) for a degenerate triangle)
    uint32_t material = 0;
    uint32_t normals[3] = {0, 0, 0};  // octahedral 2 x 16 bits; all 0 when has_normals is false
    Vec2f uv[3];
    float uv_area_ratio = 0.0f;       // texture-space area / world-space area (0 without uvs)
    uint32_t tangent = 0;             // octahedral world tangent dp/du, for normal maps (kHasTangent)
    uint32_t flags = 0;               // kHasNormals | kHasUvs | kHasTangent | kNegativeBitangent
};
static_assert(sizeof(ShadingTriangle) == 64, "one cache line per triangle");

inline constexpr uint32_t kHasNormals = 1u;
inline constexpr uint32_t kHasUvs = 2u;
inline constexpr uint32_t kHasTangent = 4u;
inline constexpr uint32_t kNegativeBitangent = 8u;

// Octahedral encoding of a unit vector into 2 x 16 bits (x in the low half).
RF_HDI uint32_t encode_octahedral(Vec3f n) {
    float l1 = fabsf(n.x) + fabsf(n.y) + fabsf(n.z);
    if (!(l1 > 0.0f)) return 0x7FFF7FFFu;  // +z-ish for a null vector
    float u = n.x / l1, v = n.y / l1;
    if (n.z < 0.0f) {
        float fu = (1.0f - fabsf(v)) * (u >= 0.0f ? 1.0f : -1.0f);
        float fv = (1.0f - fabsf(u)) * (v >= 0.0f ? 1.0f : -1.0f);
        u = fu;
        v = fv;
    }
    auto quantise = [](float x) {
        float q = rintf((fminf(fmaxf(x, -1.0f), 1.0f) * 0.5f + 0.5f) * 65535.0f);
        return uint32_t(q);
    };
    return quantise(u) | (quantise(v) << 16);
}

RF_HDI Vec3f decode_octahedral(uint32_t code) {
    float u = float(code & 0xFFFFu) * (2.0f / 65535.0f) - 1.0f;
    float v = float(code >> 16) * (2.0f / 65535.0f) - 1.0f;
    Vec3f n(u, v, 1.0f - fabsf(u) - fabsf(v));
    if (n.z < 0.0f) {
        float x = (1.0f - fabsf(v)) * (u >= 0.0f ? 1.0f : -1.0f);
        float y = (1.0f - fabsf(u)) * (v >= 0.0f ? 1.0f : -1.0f);
        n.x = x;
        n.y = y;
    }
    return normalize(n);
}

// The attributes at a hit, as rf::surface_at computes them from the meshes
// (the tangent, for normal maps, is the triangle's: mesh tangents are
// averaged over its corners).
RF_HDI SurfaceHit shading_surface(const ShadingTriangle& t, const Ray& ray, const Hit& hit) {
    SurfaceHit s;
    s.position = ray.org + ray.dir * hit.t;
    s.geometric_normal = t.geometric_normal;
    s.shading_normal = t.geometric_normal;
    s.material = t.material;
    const float w = 1.0f - hit.u - hit.v;
    if (t.flags & kHasNormals) {
        Vec3f n = decode_octahedral(t.normals[0]) * w + decode_octahedral(t.normals[1]) * hit.u +
                  decode_octahedral(t.normals[2]) * hit.v;
        float nl = length(n);
        if (nl > 0.0f && is_finite(nl)) s.shading_normal = n / nl;
    }
    if (t.flags & kHasUvs) {
        s.uv = t.uv[0] * w + t.uv[1] * hit.u + t.uv[2] * hit.v;
        s.uv_area_ratio = t.uv_area_ratio;
    }
    if (t.flags & kHasTangent) {
        s.tangent = decode_octahedral(t.tangent);
        s.tangent_sign = (t.flags & kNegativeBitangent) ? -1.0f : 1.0f;
    }
    return s;
}

// The record of one world-space triangle `tri` of a mesh with vertex
// `normals` and `uvs` (each empty or one per vertex; vertex indices `idx`,
// normals taken to world space by `normal_matrix`), without the tangent
// frame (which needs the whole scene: build_shading_triangles).
ShadingTriangle make_shading_triangle(std::span<const Vec3f> normals, std::span<const Vec2f> uvs,
                                      const Affine3f& normal_matrix, const Triangle& tri, const uint32_t idx[3],
                                      uint32_t material);

// One record per triangle of `geometry`, built in parallel; respects the
// memory budget (throws rf::Error when it would exceed it).
std::vector<ShadingTriangle> build_shading_triangles(const Scene& scene, const SceneGeometry& geometry);

}  // namespace rf
