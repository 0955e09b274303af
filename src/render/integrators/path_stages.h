// The path tracer (path.h: Kajiya 1986 with next-event estimation and MIS,
// Veach and Guibas 1995) cut into the stages of a wavefront path tracer
// (Laine, Karras and Aila 2013, "Megakernels Considered Harmful: Wavefront
// Path Tracing on GPUs"): generate a camera path, extend it (closest hit),
// shade the vertex (emission, one light sample as a shadow connection, the
// BSDF sample and Russian roulette that give the next ray), connect the
// shadow ray (visibility). Everything a path carries between stages lives in
// PathState, so the stages can run one path at a time (path_radiance, the
// megakernel) or queue by queue (the CPU wavefront driver, the CUDA kernels)
// and produce the same numbers in the same order.
//
// Random numbers: a sample's stream is consumed in the same order whichever
// way the stages are scheduled, because the only stage that may run out of
// order, the shadow test (which draws numbers on blended surfaces), takes
// them from a stream of its own derived when the connection is made.
//
// Per-sample code, shared by both backends.
#pragma once

#include <cmath>
#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/render/integrators.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/camera.h"
#include "render/bsdf.h"
#include "render/integrators/surface_trace.h"
#include "render/light_sampling.h"
#include "math/random.h"
#include "render/texture_lod.h"

namespace rf {

struct PathSettings {
    int max_depth = 8;          // bounces after the camera ray
    int rr_depth = 3;           // Russian roulette from this bounce on
    LightSampling strategy = LightSampling::Mis;
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

// Tag of the stream a shadow ray draws its numbers from (RandomStream::derive).
inline constexpr uint32_t kShadowStreamTag = 0x53484457u;

RF_HDI float power_heuristic(float pdf_a, float pdf_b) {
    float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
    return a + b > 0.0f ? a / (a + b) : 0.0f;
}

// Offsets a point off the surface to the side `dir` leaves towards.
RF_HDI Vec3f offset_origin(Vec3f p, Vec3f facing_ng, Vec3f dir, float epsilon) {
    return p + facing_ng * (dot(dir, facing_ng) >= 0.0f ? epsilon : -epsilon);
}

// One camera sample on its way through the scene.
struct PathState {
    Ray ray;                    // the ray the next extension traces
    Vec3f throughput{1.0f};
    Vec3f radiance{0.0f};       // gathered so far
    Vec3f previous_point;       // the vertex `ray` left, for weighting emission it finds
    float previous_pdf = 0.0f;  // the BSDF density that chose `ray`
    RayCone cone;               // the ray's footprint at its origin (texture LOD)
    RandomStream rng;
    uint32_t pixel = 0;         // y * width + x
    int depth = 0;              // bounces so far (pass-throughs do not count)
    int pass_throughs = 0;      // blended surfaces passed straight through
    float passed_distance = 0.0f;  // along the camera ray, through blended surfaces (depth AOV)
    bool previous_delta = true;    // the camera ray counts as delta: emitters seen directly are never weighted
};

// What an extension found: the closest surface that is not cut out (or a
// miss), on PathState::ray as extension left it (moved past the cut-outs).
struct PathHit {
    Hit hit;
    float travelled = 0.0f;  // distance skipped past cut-outs before `hit`
};

// A light sample waiting for its visibility test: if the ray reaches its
// tmax, `contribution` is added to the radiance of path `path`.
struct ShadowConnection {
    Ray ray;
    Vec3f contribution{0.0f};
    RandomStream rng;   // for blended surfaces along the ray (derived, see above)
    uint32_t path = 0;  // the caller's index of the path (the stages do not read it)
};

// Stage 1, generate: a path starting with `ray`, drawing on `rng` from here on.
RF_HDI PathState start_path(const Ray& ray, const RandomStream& rng, uint32_t pixel, const PathSettings& settings) {
    PathState path;
    path.ray = ray;
    path.previous_point = ray.org;
    path.cone = RayCone{0.0f, settings.pixel_spread};
    path.rng = rng;
    path.pixel = pixel;
    return path;
}

// Stage 1, generate, from the camera: pixel (x, y) of sample `sample`, with
// its jittered film position and lens position drawn first from the pixel's
// stream, as the progressive renderer does.
RF_HDI PathState generate_camera_path(const CameraFrame& camera, int x, int y, int width, int height,
                                      uint32_t sample, uint32_t seed, const PathSettings& settings) {
    const uint32_t pixel = uint32_t(y) * uint32_t(width) + uint32_t(x);
    RandomStream rng(pixel, sample, seed);
    const Vec2f jitter = rng.next2();
    const Vec2f lens = rng.next2();
    const Ray ray = camera.generate(float(x) + jitter.x, float(y) + jitter.y, width, height, lens.x, lens.y);
    return start_path(ray, rng, pixel, settings);
}

// Stage 2, extend, second half: `first_hit` is the closest hit of path.ray
// (from a batch query, say); walks on past cut-outs.
template <class Tracer, class View>
RF_HD PathHit complete_extension(const Tracer& tracer, const View& view, PathState& path, const Hit& first_hit) {
    PathHit found;
    found.hit = skip_cut_outs(tracer, view, path.ray, first_hit, view.ray_epsilon(), found.travelled, path.cone);
    return found;
}

// Stage 2, extend: the first surface along path.ray that is not cut out.
template <class Tracer, class View>
RF_HD PathHit extend_path(const Tracer& tracer, const View& view, PathState& path) {
    return complete_extension(tracer, view, path, tracer.intersect(path.ray));
}

// Stage 3, shade: what the path sees at `found` (a miss: the environment).
// Adds the emission found (MIS-weighted against light sampling), records the
// AOVs at the first non-blended hit (`aovs` may be null), passes blended
// surfaces through, makes at most one shadow connection (`has_shadow`; its
// `path` field is left to the caller), then samples the BSDF, plays Russian
// roulette and sets path.ray to the next ray. Returns whether the path goes on.
template <class View>
RF_HD bool shade_path(const View& view, const PathSettings& settings, PathState& path, const PathHit& found,
                      FirstHitAovs* aovs, ShadowConnection& shadow, bool& has_shadow) {
    has_shadow = false;
    const LightSet& lights = view.light_set();
    const float epsilon = view.ray_epsilon();
    const bool use_nee = settings.strategy != LightSampling::Bsdf;
    const bool use_bsdf_hits = settings.strategy != LightSampling::Nee;
    const bool mis = settings.strategy == LightSampling::Mis;
    const Vec3f dir = normalize(path.ray.dir);

    if (!found.hit.found()) {
        if (lights.environment.emits()) {
            float weight = 1.0f;
            if (!path.previous_delta) {
                if (!use_bsdf_hits) weight = 0.0f;
                else if (mis) weight = power_heuristic(path.previous_pdf, environment_light_pdf(lights, dir));
            }
            if (weight > 0.0f) path.radiance += path.throughput * lights.environment.radiance(dir) * weight;
        }
        return false;
    }
    SurfaceInteraction si;
    make_surface_interaction(view, path.ray, found.hit, found.travelled, path.cone, si);
    const Vec3f p = si.surface.position;
    const Vec3f ng = si.facing_geometric;

    // Thin transparency: a BLEND surface is passed straight through with
    // probability 1 - alpha, which averages to alpha-blending.
    if (si.alpha_mode == AlphaMode::Blend && si.material.alpha < 1.0f && path.pass_throughs < kMaxPassThroughs &&
        path.rng.next() >= si.material.alpha) {
        ++path.pass_throughs;
        if (path.depth == 0) path.passed_distance += si.distance;
        path.cone = path.cone.propagate(si.distance);
        path.ray.org = p - ng * epsilon;
        path.ray.tmin = 0.0f;
        path.ray.tmax = kInfinity;
        return true;
    }
    const bool first_hit = path.depth == 0 && aovs;
    if (first_hit) {
        aovs->normal = si.facing_shading;
        aovs->depth = path.passed_distance + si.distance;
    }

    const Vec3f emission = si.material.emission;
    if ((si.front_face || si.two_sided_emission) && max_component(emission) > 0.0f) {
        float weight = 1.0f;
        if (!path.previous_delta) {
            if (!use_bsdf_hits) weight = 0.0f;
            else if (mis)
                weight = power_heuristic(path.previous_pdf,
                                         area_light_pdf(view, lights, si.hit.prim, path.previous_point, p, dir));
        }
        path.radiance += path.throughput * emission * weight;
    }
    if (path.depth >= settings.max_depth) {
        if (first_hit) aovs->albedo = si.material.base_color;
        return false;
    }

    const float eta = si.front_face ? 1.0f / si.material.ior : si.material.ior;
    const Vec3f wo = -dir;
    const Bsdf bsdf = Bsdf::make(si.material, si.facing_shading, ng, eta, wo);
    if (first_hit) aovs->albedo = bsdf.albedo();

    if (use_nee && !bsdf.is_delta()) {
        const float u_select = path.rng.next();
        const Vec2f u_light = path.rng.next2();
        LightSample ls;
        if (sample_light(view, lights, p, u_select, u_light, ls) && ls.pdf > 0.0f) {
            float bsdf_pdf = 0.0f;
            const Vec3f f = bsdf.evaluate(wo, ls.wi, bsdf_pdf);
            if (max_component(f) > 0.0f) {
                shadow.ray.org = offset_origin(p, ng, ls.wi, epsilon);
                shadow.ray.dir = ls.wi;
                shadow.ray.tmin = 0.0f;
                shadow.ray.tmax = ls.distance < kInfinity ? ls.distance - 2.0f * epsilon : kInfinity;
                if (shadow.ray.tmax > 0.0f) {
                    const float weight = (ls.delta || !mis) ? 1.0f : power_heuristic(ls.pdf, bsdf_pdf);
                    shadow.contribution = path.throughput * f * ls.radiance * (weight / ls.pdf);
                    shadow.rng = path.rng.derive(kShadowStreamTag);
                    has_shadow = true;
                }
            }
        }
    } else if (use_nee) {
        path.rng.next();  // keep the dimension count of a vertex fixed
        path.rng.next2();
    }

    BsdfSample bs;
    const float u_lobe = path.rng.next();
    const Vec2f u_dir = path.rng.next2();
    if (!bsdf.sample(wo, u_lobe, u_dir, bs)) return false;
    path.throughput *= bs.weight;
    if (!(max_component(path.throughput) > 0.0f) || !is_finite(path.throughput)) return false;
    path.previous_point = p;
    path.previous_pdf = bs.pdf;
    path.previous_delta = bs.delta;
    // Ray cones: the footprint travels on; a rough bounce blurs it so much
    // that the finest texture levels stop mattering.
    path.cone = path.cone.propagate(si.distance);
    if (!bs.delta) path.cone.spread = fmaxf(path.cone.spread, 0.05f);

    ++path.depth;
    if (path.depth >= settings.rr_depth) {
        const float survive = fminf(max_component(path.throughput), 0.95f);
        if (path.rng.next() >= survive) return false;
        path.throughput = path.throughput / survive;
    }
    path.ray.org = offset_origin(p, ng, bs.wi, epsilon);
    path.ray.dir = bs.wi;
    path.ray.tmin = 0.0f;
    path.ray.tmax = kInfinity;
    return true;
}

// Stage 4, connect: whether the shadow ray reaches its light (cut-outs and
// blended surfaces let it through as unoccluded() decides). The caller adds
// shadow.contribution to its path's radiance when it does.
template <class Tracer, class View>
RF_HD bool connect_shadow(const Tracer& tracer, const View& view, const ShadowConnection& shadow) {
    RandomStream rng = shadow.rng;
    return unoccluded(tracer, view, shadow.ray, view.ray_epsilon(), rng);
}

// What a finished sample adds to its pixel: NaN or infinity (a degenerate
// triangle) counts as black, and with `clamp` > 0 the radiance is scaled
// down to at most `clamp` in its largest component.
RF_HDI Vec3f film_sample(Vec3f value, float clamp) {
    if (!is_finite(value)) value = Vec3f(0.0f);
    if (clamp > 0.0f && max_component(value) > clamp) value = value * (clamp / max_component(value));
    return value;
}

}  // namespace rf
