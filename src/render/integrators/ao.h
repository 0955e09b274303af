// Ambient occlusion: the cosine-weighted fraction of directions above the
// surface (the facing geometric normal) that escape within `radius`;
// 1 = fully open, 0 = fully enclosed. Background black.
#pragma once

#include "render/integrators/surface_trace.h"
#include "math/random.h"
#include "render/sampling.h"

namespace rf {

struct AoSettings {
    int samples = 16;
    float radius = 1.0f;
};

template <class Tracer, class View>
RF_HD Vec3f ao_radiance(const Tracer& tracer, const View& view, const Ray& ray,
                        RandomStream& rng, const AoSettings& settings) {
    SurfaceInteraction si;
    float epsilon = view.ray_epsilon();
    if (!trace_surface(tracer, view, ray, epsilon, si)) return Vec3f(0.0f);
    Frame frame = Frame::from_normal(si.facing_geometric);
    Vec3f origin = si.surface.position + si.facing_geometric * epsilon;
    int open = 0;
    for (int i = 0; i < settings.samples; ++i) {
        Ray probe;
        probe.org = origin;
        probe.dir = frame.to_world(sample_cosine_hemisphere(rng.next2()));
        probe.tmin = 0.0f;
        probe.tmax = settings.radius;
        if (!tracer.occluded(probe)) ++open;
    }
    return Vec3f(float(open) / float(settings.samples));
}

}  // namespace rf
