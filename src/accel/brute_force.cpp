#include "accel/brute_force.h"

#include <limits>

#include "trace/triangle_intersect.h"

namespace rf {

Hit BruteForceAccel::intersect(const Ray& ray) const {
    const WatertightRay tri_ray = WatertightRay::make(ray);
    Hit hit;
    float tmax = ray.tmax;
    const auto count = static_cast<uint32_t>(geometry_.triangles.size());
    for (uint32_t i = 0; i < count; ++i) {
        TriangleHit candidate;
        if (intersect_triangle(tri_ray, geometry_.triangles[i], ray.tmin, tmax, candidate)) {
            hit = Hit{candidate.t, candidate.u, candidate.v, i};
            tmax = candidate.t;
        }
    }
    return hit;
}

bool BruteForceAccel::occluded(const Ray& ray) const {
    const WatertightRay tri_ray = WatertightRay::make(ray);
    for (const Triangle& triangle : geometry_.triangles) {
        TriangleHit candidate;
        if (intersect_triangle(tri_ray, triangle, ray.tmin, ray.tmax, candidate)) return true;
    }
    return false;
}

AccelStats BruteForceAccel::stats() const {
    AccelStats s;
    s.name = "brute";
    s.sah_cost = std::numeric_limits<double>::quiet_NaN();
    s.quality_cost = std::numeric_limits<double>::quiet_NaN();
    return s;
}

}  // namespace rf
