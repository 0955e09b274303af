// The ray mix every acceleration-structure test traces against brute force:
// random origins and directions, rays aimed at triangles (mostly hits),
// axis-aligned and zero-component directions, and [tmin, tmax] limits.
#pragma once

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include "accel_test_scenes.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::test {

inline std::vector<Ray> make_rays(const SceneGeometry& g, size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    const Vec3f margin = g.bounds.extent() * 0.25f + Vec3f(1e-3f);
    const Box3f around{g.bounds.lo - margin, g.bounds.hi + margin};
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::uniform_int_distribution<size_t> pick(0, g.triangles.size() - 1);
    std::vector<Ray> rays;
    for (size_t i = 0; i < count; ++i) {
        Ray ray;
        ray.org = random_in_box(rng, around);
        switch (i % 5) {
            case 0: ray.dir = random_direction(rng); break;
            case 1:
            case 2: {
                const Triangle& tri = g.triangles[pick(rng)];
                float b1 = unit(rng), b2 = unit(rng);
                if (b1 + b2 > 1.0f) { b1 = 1.0f - b1; b2 = 1.0f - b2; }
                ray.dir = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2 - ray.org;
                break;
            }
            case 3: {  // one or two zero components
                Vec3f d = random_direction(rng);
                d[static_cast<int>(i % 3)] = 0.0f;
                if (i % 2) d[static_cast<int>((i + 1) % 3)] = 0.0f;
                if (length_squared(d) == 0.0f) d = Vec3f(1, 0, 0);
                ray.dir = d;
                break;
            }
            case 4: {  // aimed at a vertex, distance-limited
                const Triangle& tri = g.triangles[pick(rng)];
                ray.dir = tri.v1 - ray.org;
                ray.tmin = unit(rng) * 0.5f;
                ray.tmax = 0.5f + unit(rng);
                break;
            }
        }
        if (i % 7 == 0) ray.tmax = unit(rng) * length(g.bounds.extent()) / std::max(length(ray.dir), 1e-20f);
        rays.push_back(ray);
    }
    return rays;
}

}  // namespace rf::test
