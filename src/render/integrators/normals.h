// Normals integrator: the shading normal, turned to face the viewer, as a
// colour 0.5 * (n + 1). Background black. A quick check of geometry,
// normals and camera.
#pragma once

#include "render/integrators/surface_trace.h"

namespace rf {

template <class Tracer, class View>
RF_HD Vec3f normals_radiance(const Tracer& tracer, const View& view, const Ray& ray) {
    SurfaceInteraction si;
    if (!trace_surface(tracer, view, ray, view.ray_epsilon(), si)) return Vec3f(0.0f);
    return (si.facing_shading + Vec3f(1.0f)) * 0.5f;
}

}  // namespace rf
