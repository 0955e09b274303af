// The integrators' tracer with a count of the closest-hit and shadow queries
// it answers, over any tracer (trace/tracers.h on the GPU, an rf::Accel on
// the CPU), so both backends report the same rays. Count: the counter type
// (uint64_t per CPU task, uint32_t per GPU thread).
#pragma once

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"

namespace rf {

template <class Tracer, class Count>
struct CountingTracer {
    const Tracer& tracer;
    Count* closest;
    Count* shadow;
    RF_HDI Hit intersect(const Ray& ray) const {
        ++*closest;
        return tracer.intersect(ray);
    }
    RF_HDI bool occluded(const Ray& ray) const {
        ++*shadow;
        return tracer.occluded(ray);
    }
};

}  // namespace rf
