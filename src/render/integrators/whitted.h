// Whitted-style ray tracing (Whitted 1980, "An Improved Illumination Model
// for Shaded Display"): direct light with shadow rays at every surface,
// perfect mirror reflection and Fresnel-weighted refraction traced
// recursively. Written as a loop over a fixed-size work stack instead of
// recursion so that the same code runs on the GPU.
//
// Material model, mapped from glTF metallic-roughness (deliberately simple):
//   transmission lobe  T = transmission * (1 - metallic): smooth dielectric,
//                      exact Fresnel reflectance F, refraction tinted by base_color;
//   mirror lobe        M = metallic * (1 - roughness): perfect reflection tinted by base_color;
//   diffuse lobe       D = 1 - T - M: Lambert with base_color (rough metal falls
//                      here too, a crude stand-in for a glossy lobe).
// Local shading of the diffuse lobe: Lambert, or (for the look of the GPU ray tracers it reproduces) Lambert
// plus a Phong or Blinn-Phong highlight per light with specular colour F0 =
// mix(0.04, base_color, metallic) and exponent 2 / alpha^2 - 2 (alpha =
// roughness^2; Walter et al. 2007's Beckmann-Phong correspondence, halved for
// Phong's reflected-vector form).
// Reflections and refractions have separate depth limits (Bogolepov et al. trace one
// reflection and two refractions by default).
// Light reaches diffuse surfaces only directly (point, spot, directional
// lights and area_light_samples points on emissive triangles), plus the
// material's ambient term (Material::ambient, zero unless a scene sets it);
// emission is added where a ray sees an emitter. Shadow rays treat every surface as
// opaque, glass included (classic Whitted); alpha BLEND surfaces let
// (1 - alpha) of the ray continue behind them.
#pragma once

#include <cmath>
#include <new>

#include "rayforge/render/integrators.h"
#include "rayforge/scene/light.h"
#include "render/area_lights.h"
#include "render/integrators/surface_trace.h"
#include "render/light_sampling.h"
#include "math/random.h"
#include "render/sampling.h"

namespace rf {

struct WhittedSettings {
    int reflection_depth = 1;       // mirror and Fresnel reflections along one path
    int refraction_depth = 2;       // refractions (and blended pass-throughs) along one path
    WhittedShading shading = WhittedShading::Lambert;
    int area_light_samples = 4;     // shadow rays towards area lights per shading point
    float min_weight = 1e-3f;       // branches contributing less than this are not traced
};

// Work items pending beyond this many are dropped (their energy is lost);
// a DFS with two branches per bounce needs about 2 * (reflection + refraction
// depth) entries.
inline constexpr int kWhittedStackSize = 64;
inline constexpr int kWhittedMaxDepth = 30;

// Fresnel reflectance of a smooth dielectric for unpolarised light; eta =
// n_incident / n_transmitted, cos_i > 0. 1 under total internal reflection.
RF_HDI float fresnel_dielectric(float cos_i, float eta) {
    float sin2_t = eta * eta * fmaxf(0.0f, 1.0f - cos_i * cos_i);
    if (sin2_t >= 1.0f) return 1.0f;
    float cos_t = sqrtf(1.0f - sin2_t);
    float rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    float rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return 0.5f * (rs * rs + rp * rp);
}

// Refracted direction of unit `d` through a surface with unit normal `n`
// facing the incident side; false under total internal reflection.
RF_HDI bool refract(Vec3f d, Vec3f n, float eta, Vec3f& out) {
    float cos_i = -dot(d, n);
    float sin2_t = eta * eta * fmaxf(0.0f, 1.0f - cos_i * cos_i);
    if (sin2_t >= 1.0f) return false;
    float cos_t = sqrtf(1.0f - sin2_t);
    out = normalize(d * eta + n * (eta * cos_i - cos_t));
    return true;
}

// Highlight of one light for the Phong / Blinn-Phong options: the lobe value
// times cos(theta_i), relative to the light's incident radiance or irradiance.
RF_HDI float whitted_highlight(WhittedShading shading, Vec3f n, Vec3f wo, Vec3f wi, float roughness) {
    if (shading == WhittedShading::Lambert) return 0.0f;
    float alpha = fmaxf(roughness * roughness, 1e-3f);
    float exponent = fminf(2.0f / (alpha * alpha) - 2.0f, 1e4f);
    if (!(exponent > 0.0f)) return 0.0f;
    float cos_lobe;
    if (shading == WhittedShading::Phong) {
        exponent *= 0.25f;
        cos_lobe = dot(reflect(-wo, n), wi);
    } else {
        cos_lobe = dot(n, normalize(wo + wi));
    }
    if (cos_lobe <= 0.0f) return 0.0f;
    // Normalised so the lobe reflects about the same energy at any exponent.
    return (exponent + 2.0f) * (0.5f * kInvPi) * powf(cos_lobe, exponent) * fmaxf(dot(n, wi), 0.0f);
}

// Irradiance-like sum over lights of L_i * cos(theta_i) at a point with
// facing shading normal n and facing geometric normal ng (the integrand of
// the Lambert reflection without the albedo / pi); with the Phong or Blinn
// options `highlight` receives the sum of L_i times the specular lobe.
template <class Tracer, class View>
RF_HD Vec3f direct_lighting(const Tracer& tracer, const View& view, const SurfaceInteraction& si, Vec3f wo,
                            RandomStream& rng, const WhittedSettings& settings, Vec3f& highlight) {
    highlight = Vec3f(0.0f);
    const Vec3f n = si.facing_shading;
    const Vec3f ng = si.facing_geometric;
    const float epsilon = view.ray_epsilon();
    const Vec3f origin = si.surface.position + ng * epsilon;
    Vec3f sum(0.0f);

    for (uint32_t i = 0; i < view.light_count(); ++i) {
        const Light& light = view.light(i);
        Vec3f wi;
        float distance = kInfinity;
        Vec3f incident;
        if (light.type == LightType::Directional) {
            wi = normalize(-light.direction);
            incident = light.color * light.intensity;
        } else {
            Vec3f to_light = light.position - origin;
            float d2 = dot(to_light, to_light);
            if (!(d2 > 0.0f)) continue;
            distance = sqrtf(d2);
            wi = to_light / distance;
            incident = light.color * (light.intensity / d2);
            if (light.type == LightType::Spot)
                incident *= spot_falloff(light, dot(-wi, normalize(light.direction)));
        }
        float cos_theta = dot(n, wi);
        if (cos_theta <= 0.0f || dot(ng, wi) <= 0.0f || max_component(incident) <= 0.0f) continue;
        Ray shadow;
        shadow.org = origin;
        shadow.dir = wi;
        shadow.tmin = 0.0f;
        shadow.tmax = distance < kInfinity ? distance * (1.0f - 1e-4f) : kInfinity;
        if (unoccluded(tracer, view, shadow, epsilon, rng)) {
            sum += incident * cos_theta;
            highlight += incident * whitted_highlight(settings.shading, n, wo, wi, si.material.roughness);
        }
    }

    const EmitterTable& emitters = view.emitters();
    if (emitters.count > 0 && settings.area_light_samples > 0) {
        Vec3f area_sum(0.0f), area_highlight(0.0f);
        const float inv_samples = 1.0f / float(settings.area_light_samples);
        for (int s = 0; s < settings.area_light_samples; ++s) {
            // Stratified choice of the emitter: equal-power lights get equal shares.
            float u_select = fminf((float(s) + rng.next()) * inv_samples, 0.99999994f);
            Vec2f u_point = rng.next2();
            AreaLightSample ls = sample_area_light(emitters, view.triangles(), u_select, u_point);
            if (!(ls.pdf_area > 0.0f)) continue;
            Vec3f d = ls.position - origin;
            float d2 = dot(d, d);
            if (!(d2 > 0.0f)) continue;
            float dist = sqrtf(d2);
            Vec3f wi = d / dist;
            float cos_theta = dot(n, wi);
            if (cos_theta <= 0.0f || dot(ng, wi) <= 0.0f) continue;
            SurfaceHit light_surface = view.emitter_surface(ls);
            const ShadingMaterial& lm = view.material(light_surface.material);
            float cos_light = -dot(ls.normal, wi);
            if (lm.two_sided_emission) cos_light = fabsf(cos_light);
            if (cos_light <= 0.0f) continue;
            Ray shadow;
            shadow.org = origin;
            shadow.dir = d;               // t = 1 at the light
            shadow.tmin = 0.0f;
            shadow.tmax = 1.0f - epsilon / dist;
            if (!unoccluded(tracer, view, shadow, epsilon, rng)) continue;
            Vec3f emitted = evaluate_material(view, lm, light_surface.uv).emission;
            Vec3f incident = emitted * (cos_light / (d2 * ls.pdf_area));
            area_sum += incident * cos_theta;
            area_highlight += incident * whitted_highlight(settings.shading, n, wo, wi, si.material.roughness);
        }
        sum += area_sum * inv_samples;
        highlight += area_highlight * inv_samples;
    }
    return sum;
}

template <class Tracer, class View>
RF_HD Vec3f whitted_radiance(const Tracer& tracer, const View& view, const Ray& camera_ray,
                             RandomStream& rng, const WhittedSettings& settings) {
    struct WorkItem {
        Ray ray;
        Vec3f weight;
        int reflections, refractions;
    };
    // Raw slots, made as items are pushed: default-constructing 64 rays per
    // sample (their members have initialisers) cost more than most samples'
    // whole stack traffic.
    union Slot {
        WorkItem item;
        RF_HDI Slot() {}
    };
    Slot stack[kWhittedStackSize];
    int top = 0;
    new (&stack[top++].item) WorkItem{camera_ray, Vec3f(1.0f), 0, 0};
    const float epsilon = view.ray_epsilon();
    const int max_reflections = settings.reflection_depth < kWhittedMaxDepth ? settings.reflection_depth : kWhittedMaxDepth;
    const int max_refractions = settings.refraction_depth < kWhittedMaxDepth ? settings.refraction_depth : kWhittedMaxDepth;
    Vec3f radiance(0.0f);

    auto push = [&](Vec3f org, Vec3f dir, Vec3f weight, int reflections, int refractions) {
        if (top >= kWhittedStackSize || max_component(weight) < settings.min_weight) return;
        Ray r;
        r.org = org;
        r.dir = dir;
        new (&stack[top++].item) WorkItem{r, weight, reflections, refractions};
    };

    while (top > 0) {
        const WorkItem item = stack[--top].item;
        SurfaceInteraction si;
        if (!trace_surface(tracer, view, item.ray, epsilon, si)) {
            radiance += item.weight * view.environment(normalize(item.ray.dir));
            continue;
        }
        const MaterialSample& m = si.material;
        const Vec3f p = si.surface.position;
        const Vec3f ng = si.facing_geometric;
        const Vec3f d = normalize(item.ray.dir);
        const bool may_reflect = item.reflections < max_reflections;
        const bool may_refract = item.refractions < max_refractions;
        Vec3f weight = item.weight;

        if (si.alpha_mode == AlphaMode::Blend && m.alpha < 1.0f) {
            if (may_refract)
                push(p - ng * epsilon, d, weight * (1.0f - m.alpha), item.reflections, item.refractions + 1);
            weight *= m.alpha;
        }
        if (si.front_face || si.two_sided_emission) radiance += weight * m.emission;

        float transmission = m.transmission * (1.0f - m.metallic);
        float mirror = m.metallic * (1.0f - m.roughness);
        float diffuse = fmaxf(0.0f, 1.0f - transmission - mirror);
        const Vec3f ambient = view.material_ambient(si.surface.material);
        if (diffuse > 0.0f && max_component(ambient) > 0.0f) {  // k_a * I_a, the texture's colour where there is one
            const bool textured = view.material(si.surface.material).base_color_texture != kNoTexture;
            radiance += weight * ambient * (textured ? m.base_color * diffuse : Vec3f(diffuse));
        }
        if (diffuse > 0.0f && max_component(m.base_color) > 0.0f) {
            Vec3f highlight;
            Vec3f lighting = direct_lighting(tracer, view, si, -d, rng, settings, highlight);
            radiance += weight * m.base_color * (diffuse * kInvPi) * lighting;
            if (settings.shading != WhittedShading::Lambert) {
                Vec3f specular_color = lerp(Vec3f(0.04f), m.base_color, m.metallic);
                radiance += weight * specular_color * diffuse * highlight;
            }
        }

        // Specular directions use the shading normal; origins move off the
        // surface on the side the new ray travels to.
        const Vec3f n = si.facing_shading;
        auto offset_towards = [&](Vec3f dir) { return p + ng * (dot(dir, ng) >= 0.0f ? epsilon : -epsilon); };
        if (mirror > 0.0f && may_reflect) {
            Vec3f r = reflect(d, n);
            push(offset_towards(r), r, weight * m.base_color * mirror, item.reflections + 1, item.refractions);
        }
        if (transmission > 0.0f) {
            float eta = si.front_face ? 1.0f / m.ior : m.ior;
            float cos_i = fminf(1.0f, fmaxf(0.0f, -dot(d, n)));
            float fresnel = fresnel_dielectric(cos_i, eta);
            Vec3f t;
            if (fresnel < 1.0f && refract(d, n, eta, t)) {
                if (may_refract)
                    push(offset_towards(t), t, weight * m.base_color * (transmission * (1.0f - fresnel)),
                         item.reflections, item.refractions + 1);
            } else {
                fresnel = 1.0f;  // total internal reflection
            }
            if (may_reflect) {
                Vec3f r = reflect(d, n);
                push(offset_towards(r), r, weight * (transmission * fresnel), item.reflections + 1, item.refractions);
            }
        }
    }
    return radiance;
}

}  // namespace rf
