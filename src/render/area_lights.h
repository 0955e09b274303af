// Choosing a point on the scene's emissive triangles (area lights), shared by
// both backends. Triangles are picked in proportion to their power (see
// emitter_power in light_set.h) from a cumulative table, then a point is
// drawn uniformly on the chosen triangle, so the cost per shading point is a
// fixed number of samples however many emissive triangles the scene has.
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/scene_geometry.h"
#include "render/sampling.h"

namespace rf {

struct EmitterTable {
    const uint32_t* triangles = nullptr;  // indices into the flat triangle array
    const float* cdf = nullptr;           // cdf[i] = power of emitters 0..i / total; cdf[count-1] = 1
    uint32_t count = 0;

    // Index of the emitter whose cdf interval holds u, and its probability.
    RF_HD uint32_t select(float u, float& probability) const {
        uint32_t lo = 0, hi = count - 1;
        while (lo < hi) {  // first i with cdf[i] > u
            uint32_t mid = (lo + hi) / 2;
            if (cdf[mid] > u) hi = mid;
            else lo = mid + 1;
        }
        probability = cdf[lo] - (lo > 0 ? cdf[lo - 1] : 0.0f);
        return lo;
    }
};

struct AreaLightSample {
    uint32_t prim = kInvalidId;  // flat triangle index
    float b1 = 0.0f, b2 = 0.0f;  // barycentrics of vertices 1 and 2
    Vec3f position;
    Vec3f normal;                // unit, as wound
    float pdf_area = 0.0f;       // probability density per unit area
};

// A ray and hit that reach the sampled point at t = 1, so that a scene view
// interpolates the emitter's attributes there (material, uv for emission
// textures) the way it does at any hit.
RF_HDI void emitter_ray_hit(const AreaLightSample& s, Ray& ray, Hit& hit) {
    ray.org = s.position - s.normal;
    ray.dir = s.normal;
    hit.t = 1.0f;
    hit.u = s.b1;
    hit.v = s.b2;
    hit.prim = s.prim;
}

// A point on an emitter for the random numbers u_select, u_point; pdf_area is
// 0 when the table is empty or the chosen triangle is degenerate.
RF_HD inline AreaLightSample sample_area_light(const EmitterTable& table, const Triangle* triangles,
                                               float u_select, Vec2f u_point) {
    AreaLightSample s;
    if (table.count == 0) return s;
    float probability = 0.0f;
    uint32_t i = table.select(u_select, probability);
    s.prim = table.triangles[i];
    const Triangle& tri = triangles[s.prim];
    Vec3f n = tri.geometric_normal();
    float twice_area = length(n);
    if (!(twice_area > 0.0f) || !(probability > 0.0f)) return s;
    Vec2f b = sample_uniform_triangle(u_point);
    s.b1 = b.x;
    s.b2 = b.y;
    s.position = tri.v0 * (1.0f - b.x - b.y) + tri.v1 * b.x + tri.v2 * b.y;
    s.normal = n / twice_area;
    s.pdf_area = probability / (0.5f * twice_area);
    return s;
}

}  // namespace rf
