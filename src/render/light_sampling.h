// Next-event estimation: choose one light from a LightSet, a point or
// direction on it, and report the densities multiple importance sampling
// needs (Veach & Guibas 1995, "Optimally Combining Sampling Techniques for
// Monte Carlo Rendering"). All densities are per unit solid angle at the
// shading point and include the probability of having chosen the light, so
// a BSDF-sampled ray that hits an emitter can be weighted against the same
// strategy with area_light_pdf / environment_light_pdf.
//
// `View` provides `material(uint32_t)` -> const ShadingMaterial&,
// `texture(int32_t)` (for evaluate_material) and
// `emitter_surface(const AreaLightSample&)` -> SurfaceHit.
#pragma once

#include <cmath>
#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/light.h"
#include "render/area_lights.h"
#include "render/environment_map.h"
#include "render/light_set.h"
#include "render/material_eval.h"

namespace rf {

struct LightSample {
    Vec3f wi;               // unit direction from the shading point to the light
    float distance;         // to the light point; kInfinity for directional lights and the environment
    Vec3f radiance;         // radiance (or for delta lights: intensity/d^2 or irradiance, falloff applied) arriving at p, not occluded-tested
    float pdf;              // solid-angle density INCLUDING the selection probability; for delta lights (point/spot/directional): the selection probability
    bool delta;
};

// Angular falloff of a glTF (KHR_lights_punctual) spot light for the cosine
// between its axis and the direction to the lit point: 1 inside the inner
// cone, 0 outside the outer one, and in between the square of the linear
// ramp in cosine.
RF_HDI float spot_falloff(const Light& light, float cos_angle) {
    float cos_outer = cosf(light.outer_cone_radians);
    float cos_inner = cosf(light.inner_cone_radians);
    if (cos_inner - cos_outer <= 1e-6f) return cos_angle >= cos_outer ? 1.0f : 0.0f;
    float t = fminf(fmaxf((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0f), 1.0f);
    return t * t;
}

// A light sample seen from point p for the random numbers u_select (which
// light, and which emitter within the area group) and u (where on it).
// False when the sample carries no light: nothing emits, the light is behind
// the point's reach (outside a spot cone, the back of a one-sided emitter),
// or the density vanished. A false sample still counts as a zero sample.
template <class View>
RF_HD bool sample_light(const View& view, const LightSet& lights, Vec3f p, float u_select, Vec2f u,
                        LightSample& out) {
    if (lights.selection_count == 0) return false;
    float selection = 0.0f, u_within = 0.0f;
    uint32_t entry = lights.select(fminf(fmaxf(u_select, 0.0f), 0.99999994f), selection, u_within);
    if (!(selection > 0.0f)) return false;

    if (entry < lights.light_count) {
        const Light& light = lights.lights[entry];
        out.delta = true;
        out.pdf = selection;
        if (light.type == LightType::Directional) {
            out.wi = normalize(-light.direction);
            out.distance = kInfinity;
            out.radiance = light.color * light.intensity;
        } else {
            Vec3f to_light = light.position - p;
            float d2 = dot(to_light, to_light);
            if (!(d2 > 0.0f)) return false;
            out.distance = sqrtf(d2);
            out.wi = to_light / out.distance;
            out.radiance = light.color * (light.intensity / d2);
            if (light.type == LightType::Spot)
                out.radiance *= spot_falloff(light, dot(-out.wi, normalize(light.direction)));
        }
        return is_finite(out.wi) && max_component(out.radiance) > 0.0f;
    }

    if (entry == lights.area_entry()) {
        AreaLightSample s = sample_area_light(lights.emitters, lights.triangles, u_within, u);
        if (!(s.pdf_area > 0.0f)) return false;
        Vec3f d = s.position - p;
        float d2 = dot(d, d);
        if (!(d2 > 0.0f)) return false;
        float distance = sqrtf(d2);
        Vec3f wi = d / distance;
        float cos_light = -dot(s.normal, wi);  // > 0 on the side the triangle faces
        SurfaceHit surface = view.emitter_surface(s);
        const ShadingMaterial& m = view.material(surface.material);
        if (cos_light <= 0.0f && !m.two_sided_emission) return false;  // one-sided: dark from behind
        float abs_cos = fabsf(cos_light);
        if (!(abs_cos > 0.0f)) return false;
        out.wi = wi;
        out.distance = distance;
        out.radiance = evaluate_material(view, m, surface.uv).emission;
        out.pdf = selection * s.pdf_area * d2 / abs_cos;
        out.delta = false;
        return out.pdf > 0.0f && out.pdf < kInfinity && max_component(out.radiance) > 0.0f;
    }

    // The environment.
    Vec3f dir;
    float pdf = 0.0f;
    Vec3f radiance = lights.environment.sample(u, dir, pdf);
    if (!(pdf > 0.0f)) return false;
    out.wi = dir;
    out.distance = kInfinity;
    out.radiance = radiance;
    out.pdf = selection * pdf;
    out.delta = false;
    return max_component(radiance) > 0.0f;
}

// Density (solid angle, selection included) with which sample_light would
// have produced the point `hit_point` on emissive triangle `prim` seen from
// `p` along unit `wi`; 0 when `prim` is not in the emitter table.
template <class View>
RF_HD float area_light_pdf(const View& view, const LightSet& lights, uint32_t prim, Vec3f p, Vec3f hit_point,
                           Vec3f wi) {
    (void)view;  // the density does not depend on the material
    uint32_t i = lights.emitter_index(prim);
    if (i >= lights.emitters.count) return 0.0f;
    // The same expressions as EmitterTable::select and sample_area_light, so
    // both strategies agree on the density of the same point.
    float probability = lights.emitters.cdf[i] - (i > 0 ? lights.emitters.cdf[i - 1] : 0.0f);
    Vec3f n = lights.triangles[prim].geometric_normal();
    float twice_area = length(n);
    if (!(twice_area > 0.0f) || !(probability > 0.0f)) return 0.0f;
    float pdf_area = probability / (0.5f * twice_area);
    Vec3f d = hit_point - p;
    float d2 = dot(d, d);
    float abs_cos = fabsf(dot(n / twice_area, wi));
    if (!(abs_cos > 0.0f)) return 0.0f;
    return lights.selection_probability(lights.area_entry()) * pdf_area * d2 / abs_cos;
}

// Density (solid angle, selection included) with which sample_light picks
// the environment along unit `wi`; 0 when the environment is not a light.
RF_HDI float environment_light_pdf(const LightSet& lights, Vec3f wi) {
    float selection = lights.selection_probability(lights.environment_entry());
    if (!(selection > 0.0f)) return 0.0f;
    return selection * lights.environment.pdf(wi);
}

}  // namespace rf
