// Unidirectional path tracing (Kajiya 1986, "The Rendering Equation") with
// next-event estimation and multiple importance sampling (Veach and Guibas
// 1995, "Optimally Combining Sampling Techniques for Monte Carlo Rendering",
// power heuristic with beta = 2), as in Garanzha 2014's CentiLeo renderer (eq. 1.2
// with explicit light connections, combined by MIS).
//
// At every vertex: emission seen by the previous BSDF sample is weighted
// against the chance that light sampling would have found it; one light
// sample (light_sampling.h) is connected with a shadow ray and weighted
// against the BSDF's chance of finding it; then the BSDF (bsdf.h) chooses the
// next direction. Russian roulette ends paths whose throughput is small after
// rr_depth bounces. Per-sample code, shared by both backends.
//
// The work of one vertex is split into the stages of path_stages.h (extend,
// shade, connect); path_radiance runs them one path at a time, the wavefront
// drivers queue by queue, so both compute the same image.
#pragma once

#include <cmath>

#include "render/bsdf.h"
#include "render/integrators/path_stages.h"
#include "render/integrators/surface_trace.h"
#include "math/random.h"

namespace rf {

// The radiance one camera ray brings back (the megakernel: every stage of
// path_stages.h in turn, for one path). `rng` is the sample's stream, left
// advanced past the numbers the path drew.
template <class Tracer, class View>
RF_HD Vec3f path_radiance(const Tracer& tracer, const View& view, Ray ray, RandomStream& rng,
                          const PathSettings& settings, FirstHitAovs* aovs = nullptr) {
    PathState path = start_path(ray, rng, 0, settings);
    for (;;) {
        const PathHit found = extend_path(tracer, view, path);
        ShadowConnection shadow;
        bool has_shadow = false;
        const bool goes_on = shade_path(view, settings, path, found, aovs, shadow, has_shadow);
        // The light sample of this vertex is added after its emission and
        // before the next vertex's, the order the wavefront keeps as well.
        if (has_shadow && connect_shadow(tracer, view, shadow)) path.radiance += shadow.contribution;
        if (!goes_on) break;
    }
    rng = path.rng;
    return path.radiance;
}

// The AOVs alone (for integrators other than the path tracer).
template <class Tracer, class View>
RF_HD FirstHitAovs first_hit_aovs(const Tracer& tracer, const View& view, const Ray& ray) {
    FirstHitAovs aovs;
    SurfaceInteraction si;
    if (!trace_surface(tracer, view, ray, view.ray_epsilon(), si)) return aovs;
    const float eta = si.front_face ? 1.0f / si.material.ior : si.material.ior;
    aovs.albedo = Bsdf::make(si.material, si.facing_shading, si.facing_geometric, eta).albedo();
    aovs.normal = si.facing_shading;
    aovs.depth = si.distance;
    return aovs;
}

}  // namespace rf
