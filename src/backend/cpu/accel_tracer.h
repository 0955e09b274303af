// The CPU integrators' tracer: an rf::Accel (any structure, one virtual call
// per query), optionally logging every query it answers (the render bench
// replays a pass's rays without shading them).
#pragma once

#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/render/render.h"

namespace rf {

struct AccelTracer {
    const Accel* accel = nullptr;
    std::vector<TracedRay>* log = nullptr;
    [[nodiscard]] Hit intersect(const Ray& ray) const {
        if (log) log->push_back({ray, false});
        return accel->intersect(ray);
    }
    [[nodiscard]] bool occluded(const Ray& ray) const {
        if (log) log->push_back({ray, true});
        return accel->occluded(ray);
    }
};

}  // namespace rf
