// Unidirectional path tracing (Kajiya 1986, "The Rendering Equation") with
// next-event estimation and multiple importance sampling (Veach and Guibas
// 1995, "Optimally Combining Sampling Techniques for Monte Carlo Rendering",
// power heuristic with beta = 2), as in seed 000's CentiLeo renderer (eq. 1.2
// with explicit light connections, combined by MIS).
//
// At every vertex: emission seen by the previous BSDF sample is weighted
// against the chance that light sampling would have found it; one light
// sample (light_sampling.h) is connected with a shadow ray and weighted
// against the BSDF's chance of finding it; then the BSDF (bsdf.h) chooses the
// next direction. Russian roulette ends paths whose throughput is small after
// rr_depth bounces. Per-sample code, shared by both backends.
#pragma once

#include <cmath>

#include "render/bsdf.h"
#include "render/integrators/surface_trace.h"
#include "render/light_sampling.h"
#include "render/random.h"

namespace rf {

// rf::LightSampling (rayforge/render/render.h) as integers, so that device
// code needs no public header.
inline constexpr int kLightSamplingMis = 0;
inline constexpr int kLightSamplingNee = 1;
inline constexpr int kLightSamplingBsdf = 2;

struct PathSettings {
    int max_depth = 8;          // bounces after the camera ray
    int rr_depth = 3;           // Russian roulette from this bounce on
    int strategy = kLightSamplingMis;
    float pixel_spread = 0.0f;  // ray-cone spread angle of a camera ray (texture LOD); 0 = finest level
};

// What the first surface a camera sample sees looks like, for denoisers.
struct FirstHitAovs {
    Vec3f albedo{0.0f};
    Vec3f normal{0.0f};  // facing shading normal, world space
    float depth = 0.0f;  // distance along the camera ray; 0 on a miss
};

// Blended surfaces passed through along one path before the path ends.
inline constexpr int kMaxPassThroughs = 64;

RF_HDI float power_heuristic(float pdf_a, float pdf_b) {
    float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
    return a + b > 0.0f ? a / (a + b) : 0.0f;
}

// Offsets a point off the surface to the side `dir` leaves towards.
RF_HDI Vec3f offset_origin(Vec3f p, Vec3f facing_ng, Vec3f dir, float epsilon) {
    return p + facing_ng * (dot(dir, facing_ng) >= 0.0f ? epsilon : -epsilon);
}

template <class Tracer, class View>
RF_HD Vec3f path_radiance(const Tracer& tracer, const View& view, Ray ray, RandomStream& rng,
                          const PathSettings& settings, FirstHitAovs* aovs = nullptr) {
    const LightSet& lights = view.light_set();
    const float epsilon = view.ray_epsilon();
    const bool use_nee = settings.strategy != kLightSamplingBsdf;
    const bool use_bsdf_hits = settings.strategy != kLightSamplingNee;
    const bool mis = settings.strategy == kLightSamplingMis;

    Vec3f radiance(0.0f), throughput(1.0f);
    // The previous vertex, for weighting emission that the BSDF sample finds.
    Vec3f previous_point = ray.org;
    float previous_pdf = 0.0f;
    bool previous_delta = true;  // the camera ray counts as delta: emitters seen directly are never weighted
    RayCone cone{0.0f, settings.pixel_spread};
    int pass_throughs = 0;
    float passed_distance = 0.0f;  // along the camera ray, through blended surfaces (depth AOV)

    for (int depth = 0;;) {
        SurfaceInteraction si;
        const Vec3f dir = normalize(ray.dir);
        if (!trace_surface(tracer, view, ray, epsilon, si, cone)) {
            if (lights.environment.emits()) {
                float weight = 1.0f;
                if (!previous_delta) {
                    if (!use_bsdf_hits) weight = 0.0f;
                    else if (mis) weight = power_heuristic(previous_pdf, environment_light_pdf(lights, dir));
                }
                if (weight > 0.0f) radiance += throughput * lights.environment.radiance(dir) * weight;
            }
            break;
        }
        const Vec3f p = si.surface.position;
        const Vec3f ng = si.facing_geometric;

        // Thin transparency: a BLEND surface is passed straight through with
        // probability 1 - alpha, which averages to alpha-blending.
        if (si.alpha_mode == AlphaMode::Blend && si.material.alpha < 1.0f && pass_throughs < kMaxPassThroughs &&
            rng.next() >= si.material.alpha) {
            ++pass_throughs;
            if (depth == 0) passed_distance += si.distance;
            cone = cone.propagate(si.distance);
            ray.org = p - ng * epsilon;
            ray.tmin = 0.0f;
            ray.tmax = kInfinity;
            continue;
        }
        if (depth == 0 && aovs) {
            aovs->normal = si.facing_shading;
            aovs->depth = passed_distance + si.distance;
        }

        const Vec3f emission = si.material.emission;
        if ((si.front_face || si.double_sided) && max_component(emission) > 0.0f) {
            float weight = 1.0f;
            if (!previous_delta) {
                if (!use_bsdf_hits) weight = 0.0f;
                else if (mis)
                    weight = power_heuristic(
                        previous_pdf, area_light_pdf(view, lights, si.hit.prim, previous_point, p, dir));
            }
            radiance += throughput * emission * weight;
        }
        if (depth >= settings.max_depth) {
            if (depth == 0 && aovs) aovs->albedo = si.material.base_color;
            break;
        }

        const float eta = si.front_face ? 1.0f / si.material.ior : si.material.ior;
        const Vec3f wo = -dir;
        const Bsdf bsdf = Bsdf::make(si.material, si.facing_shading, ng, eta, wo);
        if (depth == 0 && aovs) aovs->albedo = bsdf.albedo();

        if (use_nee && !bsdf.is_delta()) {
            const float u_select = rng.next();
            const Vec2f u_light = rng.next2();
            LightSample ls;
            if (sample_light(view, lights, p, u_select, u_light, ls) && ls.pdf > 0.0f) {
                float bsdf_pdf = 0.0f;
                const Vec3f f = bsdf.evaluate(wo, ls.wi, bsdf_pdf);
                if (max_component(f) > 0.0f) {
                    Ray shadow;
                    shadow.org = offset_origin(p, ng, ls.wi, epsilon);
                    shadow.dir = ls.wi;
                    shadow.tmin = 0.0f;
                    shadow.tmax = ls.distance < kInfinity ? ls.distance - 2.0f * epsilon : kInfinity;
                    if (shadow.tmax > 0.0f && unoccluded(tracer, view, shadow, epsilon, rng)) {
                        const float weight = (ls.delta || !mis) ? 1.0f : power_heuristic(ls.pdf, bsdf_pdf);
                        radiance += throughput * f * ls.radiance * (weight / ls.pdf);
                    }
                }
            }
        } else if (use_nee) {
            rng.next();  // keep the dimension count of a vertex fixed
            rng.next2();
        }

        BsdfSample bs;
        const float u_lobe = rng.next();
        const Vec2f u_dir = rng.next2();
        if (!bsdf.sample(wo, u_lobe, u_dir, bs)) break;
        throughput *= bs.weight;
        if (!(max_component(throughput) > 0.0f) || !is_finite(throughput)) break;
        previous_point = p;
        previous_pdf = bs.pdf;
        previous_delta = bs.delta;
        // Ray cones: the footprint travels on; a rough bounce blurs it so
        // much that the finest texture levels stop mattering.
        cone = cone.propagate(si.distance);
        if (!bs.delta) cone.spread = fmaxf(cone.spread, 0.05f);

        ++depth;
        if (depth >= settings.rr_depth) {
            const float survive = fminf(max_component(throughput), 0.95f);
            if (rng.next() >= survive) break;
            throughput = throughput / survive;
        }
        ray.org = offset_origin(p, ng, bs.wi, epsilon);
        ray.dir = bs.wi;
        ray.tmin = 0.0f;
        ray.tmax = kInfinity;
    }
    return radiance;
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
