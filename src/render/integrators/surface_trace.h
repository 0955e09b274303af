// Finding the surface a ray sees, shared by every integrator: the closest hit,
// its shading attributes and material (textures filtered at the level of
// detail the ray's footprint asks for, normal map applied), with alpha-masked
// (cut-out) surfaces skipped, as glTF's alpha_mode MASK asks; and the
// matching visibility test for shadow rays. Finding the hit (skip_cut_outs)
// and describing it (make_surface_interaction) are separate steps, so that a
// wavefront can run them as separate stages.
#pragma once

#include <cmath>

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "render/material_eval.h"
#include "math/random.h"
#include "render/texture_lod.h"

namespace rf {

// Cut-outs skipped along one ray before giving up (foliage stacks are far
// shallower; the bound keeps a pathological scene from looping).
inline constexpr int kMaxAlphaSkips = 64;

struct SurfaceInteraction {
    Hit hit;
    SurfaceHit surface;
    MaterialSample material;
    float distance = 0.0f;   // from the ray's origin (the ray as given, |dir| units removed)
    float lod_base = -kInfinity;  // texture level of detail before the texture's own size (texture_lod.h)
    bool two_sided_emission = true;
    AlphaMode alpha_mode = AlphaMode::Opaque;
    bool front_face = true;  // the ray arrived on the side the geometric normal points to
    Vec3f facing_geometric;  // geometric normal flipped towards the ray's origin
    Vec3f facing_shading;    // shading normal (normal map applied) flipped to the same side
};

// The shading normal bent by the material's normal map, in the frame of the
// hit's tangent (Gram-Schmidt against the interpolated normal); unchanged when
// there is no map or no tangent frame.
template <class View>
RF_HD Vec3f apply_normal_map(const View& view, const ShadingMaterial& m, const SurfaceHit& s, float lod_base) {
    if (m.normal_texture == kNoTexture || s.tangent_sign == 0.0f) return s.shading_normal;
    const Vec3f n = s.shading_normal;
    Vec3f t = s.tangent - n * dot(n, s.tangent);
    float tl = length(t);
    if (!(tl > 1e-6f)) return n;
    t = t / tl;
    const Vec3f b = cross(n, t) * s.tangent_sign;
    const Vec3f local = sample_normal_map(view, m, s.uv, lod_base);
    Vec3f mapped = t * local.x + b * local.y + n * local.z;
    float ml = length(mapped);
    return (ml > 0.0f && is_finite(ml)) ? mapped / ml : n;
}

// Texture level of detail at a hit (texture_lod.h) before the texture's own
// size: -inf (finest level) for untextured materials or a ray without a
// footprint. `distance` is from the footprint's origin.
RF_HDI float hit_lod_base(const ShadingMaterial& m, const SurfaceHit& surface, RayCone cone, float distance,
                          float cos_incidence) {
    const bool textured = m.base_color_texture != kNoTexture || m.metallic_roughness_texture != kNoTexture ||
                          m.normal_texture != kNoTexture || m.emission_texture != kNoTexture;
    if (textured && surface.uv_area_ratio > 0.0f && cone.width + cone.spread > 0.0f)
        return texture_lod_base(0.5f * log2f(surface.uv_area_ratio), cone.propagate(distance).width, cos_incidence);
    return -kInfinity;
}

// Whether `hit`, found along `ray` after `travelled` units of cut-outs
// skipped, lies on an alpha-masked surface that is cut out there. Only the
// alpha is looked up (evaluate_material's alpha: factor times base-colour
// texture alpha, saturated), so opaque and blended hits cost one material fetch.
template <class View>
RF_HD bool is_cut_out(const View& view, const Ray& ray, const Hit& hit, float travelled, RayCone cone) {
    const ShadingMaterial& m = view.material(view.material_id(hit.prim));
    if (m.alpha_mode != AlphaMode::Mask) return false;
    const SurfaceHit surface = view.surface(ray, hit);
    const float dir_length = length(ray.dir);
    const float distance = travelled + hit.t * dir_length;
    const float cos_incidence = dot(surface.geometric_normal, ray.dir) / dir_length;
    const float lod_base = hit_lod_base(m, surface, cone, distance, cos_incidence);
    float alpha = m.alpha;
    if (const auto* t = view.texture(m.base_color_texture)) alpha *= sample_texture_at(*t, surface.uv, lod_base).w;
    return saturate(alpha) < m.alpha_cutoff;
}

// Extension past cut-outs: given `hit`, the closest hit along `ray`, walks
// on while it lies on a cut-out, moving `ray` just behind each (tmax keeps
// its meaning in t units) and adding the distance skipped to `travelled`.
// Returns the first surface that is not cut out, or a miss (also after
// kMaxAlphaSkips cut-outs). On return `ray` is the ray the hit was found on.
// Split from trace_surface so that a wavefront can find the first hits of
// many rays in one batch and walk on only where a cut-out was hit.
template <class Tracer, class View>
RF_HD Hit skip_cut_outs(const Tracer& tracer, const View& view, Ray& ray, Hit hit, float epsilon, float& travelled,
                        RayCone cone = RayCone{}) {
    const float dir_length = length(ray.dir);
    for (int skip = 0;; ++skip) {
        if (!hit.found() || !is_cut_out(view, ray, hit, travelled, cone)) return hit;
        if (skip == kMaxAlphaSkips) return Hit{};
        // Resume just behind the surface, on the side away from the ray's origin.
        const SurfaceHit surface = view.surface(ray, hit);
        const bool front = dot(surface.geometric_normal, ray.dir) / dir_length < 0.0f;
        const Vec3f ng = front ? surface.geometric_normal : -surface.geometric_normal;
        const Vec3f next = surface.position - ng * epsilon;
        const float advanced = dot(next - ray.org, ray.dir) / dot(ray.dir, ray.dir);
        travelled += advanced * dir_length;
        ray.org = next;
        ray.tmax = ray.tmax - advanced;
        ray.tmin = 0.0f;
        if (!(ray.tmax > 0.0f)) return Hit{};
        hit = tracer.intersect(ray);
    }
}

// The shading description of `hit` (found, not cut out) along `ray`, after
// `travelled` units of cut-outs; `cone` is the footprint where the walk began.
template <class View>
RF_HD void make_surface_interaction(const View& view, const Ray& ray, const Hit& hit, float travelled, RayCone cone,
                                    SurfaceInteraction& out) {
    const SurfaceHit surface = view.surface(ray, hit);
    const ShadingMaterial& m = view.material(surface.material);
    const float dir_length = length(ray.dir);
    const float distance = travelled + hit.t * dir_length;
    const float cos_incidence = dot(surface.geometric_normal, ray.dir) / dir_length;
    const float lod_base = hit_lod_base(m, surface, cone, distance, cos_incidence);
    const bool front = cos_incidence < 0.0f;
    const Vec3f ng = front ? surface.geometric_normal : -surface.geometric_normal;
    Vec3f ns = apply_normal_map(view, m, surface, lod_base);
    if (dot(ns, ng) < 0.0f) ns = -ns;
    out.hit = hit;
    out.surface = surface;
    out.material = evaluate_material(view, m, surface.uv, lod_base);
    out.distance = distance;
    out.lod_base = lod_base;
    out.two_sided_emission = m.two_sided_emission;
    out.alpha_mode = m.alpha_mode;
    out.front_face = front;
    out.facing_geometric = ng;
    out.facing_shading = ns;
}

// The first non-cut-out surface along `ray`; false on a miss. `epsilon` is
// how far past a cut-out the search resumes; `cone` is the ray's footprint
// at its origin (width 0, spread 0: finest texture level everywhere).
template <class Tracer, class View>
RF_HD bool trace_surface(const Tracer& tracer, const View& view, Ray ray, float epsilon, SurfaceInteraction& out,
                         RayCone cone = RayCone{}) {
    float travelled = 0.0f;
    const Hit hit = skip_cut_outs(tracer, view, ray, tracer.intersect(ray), epsilon, travelled, cone);
    if (!hit.found()) return false;
    make_surface_interaction(view, ray, hit, travelled, cone, out);
    return true;
}

// Whether a shadow ray reaches its tmax. Opaque geometry blocks it; in scenes
// with cut-outs or blended surfaces the ray walks from hit to hit so that a
// leaf's alpha mask casts a leaf-shaped shadow (a BLEND surface lets the ray
// through with probability 1 - alpha).
template <class Tracer, class View>
RF_HD bool unoccluded(const Tracer& tracer, const View& view, Ray ray, float epsilon, RandomStream& rng) {
    if (!view.has_transparent_materials()) return !tracer.occluded(ray);
    for (int skip = 0; skip <= kMaxAlphaSkips; ++skip) {
        Hit hit = tracer.intersect(ray);
        if (!hit.found()) return true;
        const ShadingMaterial& m = view.material(view.material_id(hit.prim));
        if (m.alpha_mode == AlphaMode::Opaque) return false;
        SurfaceHit surface = view.surface(ray, hit);
        MaterialSample sample = evaluate_material(view, m, surface.uv);
        bool passes = m.alpha_mode == AlphaMode::Mask ? sample.alpha < m.alpha_cutoff : rng.next() >= sample.alpha;
        if (!passes) return false;
        // Move just past the surface along the ray; tmax stays in t units.
        float advanced = hit.t + epsilon / length(ray.dir);
        ray.org = ray.org + ray.dir * advanced;
        ray.tmax -= advanced;
        ray.tmin = 0.0f;
        if (!(ray.tmax > 0.0f)) return true;
    }
    return false;
}

}  // namespace rf
