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
// Light reaches diffuse surfaces only directly (point, spot, directional
// lights and area_light_samples points on emissive triangles); emission is
// added where a ray sees an emitter. Shadow rays treat every surface as
// opaque, glass included (classic Whitted); alpha BLEND surfaces let
// (1 - alpha) of the ray continue behind them.
#pragma once

#include <cmath>

#include "rayforge/scene/light.h"
#include "render/area_lights.h"
#include "render/integrators/surface_trace.h"
#include "render/random.h"
#include "render/sampling.h"

namespace rf {

struct WhittedSettings {
    int max_depth = 5;              // reflection/refraction bounces after the camera ray
    int area_light_samples = 4;     // shadow rays towards area lights per shading point
    float min_weight = 1e-3f;       // branches contributing less than this are not traced
};

// Work items pending beyond this many are dropped (their energy is lost);
// a DFS with two branches per bounce needs about 2 * max_depth entries.
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

// Angular falloff of a glTF spot light for the cosine between its axis and
// the direction to the shaded point.
RF_HDI float spot_attenuation(const Light& light, float cos_angle) {
    float cos_outer = cosf(light.outer_cone_radians);
    float cos_inner = cosf(light.inner_cone_radians);
    if (cos_inner - cos_outer <= 1e-6f) return cos_angle >= cos_outer ? 1.0f : 0.0f;
    float t = fminf(fmaxf((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0f), 1.0f);
    return t * t;
}

// Irradiance-like sum over lights of L_i * cos(theta_i) at a point with
// facing shading normal n and facing geometric normal ng (the integrand of
// the Lambert reflection without the albedo / pi).
template <class Tracer, class View>
RF_HD Vec3f direct_lighting(const Tracer& tracer, const View& view, const SurfaceInteraction& si,
                            RandomStream& rng, const WhittedSettings& settings) {
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
                incident *= spot_attenuation(light, dot(-wi, normalize(light.direction)));
        }
        float cos_theta = dot(n, wi);
        if (cos_theta <= 0.0f || dot(ng, wi) <= 0.0f || max_component(incident) <= 0.0f) continue;
        Ray shadow;
        shadow.org = origin;
        shadow.dir = wi;
        shadow.tmin = 0.0f;
        shadow.tmax = distance < kInfinity ? distance * (1.0f - 1e-4f) : kInfinity;
        if (!tracer.occluded(shadow)) sum += incident * cos_theta;
    }

    const EmitterTable& emitters = view.emitters();
    if (emitters.count > 0 && settings.area_light_samples > 0) {
        Vec3f area_sum(0.0f);
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
            if (lm.double_sided) cos_light = fabsf(cos_light);
            if (cos_light <= 0.0f) continue;
            Ray shadow;
            shadow.org = origin;
            shadow.dir = d;               // t = 1 at the light
            shadow.tmin = 0.0f;
            shadow.tmax = 1.0f - epsilon / dist;
            if (tracer.occluded(shadow)) continue;
            Vec3f emitted = evaluate_material(view, lm, light_surface.uv).emission;
            area_sum += emitted * (cos_theta * cos_light / (d2 * ls.pdf_area));
        }
        sum += area_sum * inv_samples;
    }
    return sum;
}

template <class Tracer, class View>
RF_HD Vec3f whitted_radiance(const Tracer& tracer, const View& view, const Ray& camera_ray,
                             RandomStream& rng, const WhittedSettings& settings) {
    struct WorkItem {
        Ray ray;
        Vec3f weight;
        int depth;
    };
    WorkItem stack[kWhittedStackSize];
    int top = 0;
    stack[top++] = {camera_ray, Vec3f(1.0f), 0};
    const float epsilon = view.ray_epsilon();
    const int max_depth = settings.max_depth < kWhittedMaxDepth ? settings.max_depth : kWhittedMaxDepth;
    Vec3f radiance(0.0f);

    auto push = [&](Vec3f org, Vec3f dir, Vec3f weight, int depth) {
        if (top >= kWhittedStackSize || max_component(weight) < settings.min_weight) return;
        Ray r;
        r.org = org;
        r.dir = dir;
        stack[top++] = {r, weight, depth};
    };

    while (top > 0) {
        WorkItem item = stack[--top];
        SurfaceInteraction si;
        if (!trace_surface(tracer, view, item.ray, epsilon, si)) {
            radiance += item.weight * view.environment(normalize(item.ray.dir));
            continue;
        }
        const MaterialSample& m = si.material;
        const Vec3f p = si.surface.position;
        const Vec3f ng = si.facing_geometric;
        const Vec3f d = normalize(item.ray.dir);
        Vec3f weight = item.weight;

        if (si.alpha_mode == AlphaMode::Blend && m.alpha < 1.0f) {
            if (item.depth < max_depth) push(p - ng * epsilon, d, weight * (1.0f - m.alpha), item.depth + 1);
            weight *= m.alpha;
        }
        if (si.front_face || si.double_sided) radiance += weight * m.emission;

        float transmission = m.transmission * (1.0f - m.metallic);
        float mirror = m.metallic * (1.0f - m.roughness);
        float diffuse = fmaxf(0.0f, 1.0f - transmission - mirror);
        if (diffuse > 0.0f && max_component(m.base_color) > 0.0f) {
            Vec3f lighting = direct_lighting(tracer, view, si, rng, settings);
            radiance += weight * m.base_color * (diffuse * kInvPi) * lighting;
        }
        if (item.depth >= max_depth) continue;

        // Specular directions use the shading normal; origins move off the
        // surface on the side the new ray travels to.
        const Vec3f n = si.facing_shading;
        auto offset_towards = [&](Vec3f dir) { return p + ng * (dot(dir, ng) >= 0.0f ? epsilon : -epsilon); };
        if (mirror > 0.0f) {
            Vec3f r = reflect(d, n);
            push(offset_towards(r), r, weight * m.base_color * mirror, item.depth + 1);
        }
        if (transmission > 0.0f) {
            float eta = si.front_face ? 1.0f / m.ior : m.ior;
            float cos_i = fminf(1.0f, fmaxf(0.0f, -dot(d, n)));
            float fresnel = fresnel_dielectric(cos_i, eta);
            Vec3f t;
            if (fresnel < 1.0f && refract(d, n, eta, t))
                push(offset_towards(t), t, weight * m.base_color * (transmission * (1.0f - fresnel)), item.depth + 1);
            else
                fresnel = 1.0f;  // total internal reflection
            Vec3f r = reflect(d, n);
            push(offset_towards(r), r, weight * (transmission * fresnel), item.depth + 1);
        }
    }
    return radiance;
}

}  // namespace rf
