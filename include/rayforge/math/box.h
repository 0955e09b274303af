// Axis-aligned bounding box. An empty box has lo = +inf, hi = -inf so that
// extending it by anything yields that thing.
#pragma once

#include <cfloat>

#include "rayforge/math/vec.h"

namespace rf {

struct Box3f {
    Vec3f lo{FLT_MAX, FLT_MAX, FLT_MAX};
    Vec3f hi{-FLT_MAX, -FLT_MAX, -FLT_MAX};

    RF_HDI static Box3f empty() { return {}; }
    RF_HDI bool is_empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
    RF_HDI void extend(Vec3f p) { lo = min(lo, p); hi = max(hi, p); }
    RF_HDI void extend(const Box3f& b) { lo = min(lo, b.lo); hi = max(hi, b.hi); }
    RF_HDI Vec3f extent() const { return hi - lo; }
    RF_HDI Vec3f center() const { return (lo + hi) * 0.5f; }
    // Full surface area; 0 for an empty box.
    RF_HDI float surface_area() const {
        if (is_empty()) return 0.0f;
        Vec3f e = extent();
        return 2.0f * (e.x * e.y + e.y * e.z + e.z * e.x);
    }
    RF_HDI int largest_axis() const {
        Vec3f e = extent();
        return (e.x >= e.y && e.x >= e.z) ? 0 : (e.y >= e.z ? 1 : 2);
    }
    RF_HDI bool contains(const Box3f& b) const {
        return b.lo.x >= lo.x && b.lo.y >= lo.y && b.lo.z >= lo.z &&
               b.hi.x <= hi.x && b.hi.y <= hi.y && b.hi.z <= hi.z;
    }
};

RF_HDI Box3f merge(Box3f a, const Box3f& b) { a.extend(b); return a; }

}  // namespace rf
