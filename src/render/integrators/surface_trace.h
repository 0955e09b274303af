// Finding the surface a ray sees, shared by every integrator: the closest hit,
// its shading attributes and material, with alpha-masked (cut-out) surfaces
// skipped, as glTF's alpha_mode MASK asks.
#pragma once

#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "render/material_eval.h"

namespace rf {

// Cut-outs skipped along one ray before giving up (foliage stacks are far
// shallower; the bound keeps a pathological scene from looping).
inline constexpr int kMaxAlphaSkips = 64;

struct SurfaceInteraction {
    Hit hit;
    SurfaceHit surface;
    MaterialSample material;
    bool double_sided = true;
    AlphaMode alpha_mode = AlphaMode::Opaque;
    bool front_face = true;  // the ray arrived on the side the geometric normal points to
    Vec3f facing_geometric;  // geometric normal flipped towards the ray's origin
    Vec3f facing_shading;    // shading normal flipped to the same side
};

// The first non-cut-out surface along `ray`; false on a miss. `epsilon` is
// how far past a cut-out the search resumes.
template <class Tracer, class View>
RF_HD bool trace_surface(const Tracer& tracer, const View& view, Ray ray, float epsilon,
                         SurfaceInteraction& out) {
    for (int skip = 0; skip <= kMaxAlphaSkips; ++skip) {
        Hit hit = tracer.intersect(ray);
        if (!hit.found()) return false;
        SurfaceHit surface = view.surface(ray, hit);
        const ShadingMaterial& m = view.material(surface.material);
        MaterialSample sample = evaluate_material(view, m, surface.uv);
        bool front = dot(surface.geometric_normal, ray.dir) < 0.0f;
        Vec3f ng = front ? surface.geometric_normal : -surface.geometric_normal;
        bool cut_out = m.alpha_mode == AlphaMode::Mask && sample.alpha < m.alpha_cutoff;
        if (cut_out) {
            // Resume just behind the surface; tmax keeps its meaning in t units.
            Vec3f next = surface.position - ng * epsilon;
            float advanced = dot(next - ray.org, ray.dir) / dot(ray.dir, ray.dir);
            ray.org = next;
            ray.tmax = ray.tmax - advanced;
            ray.tmin = 0.0f;
            if (!(ray.tmax > 0.0f)) return false;
            continue;
        }
        Vec3f ns = surface.shading_normal;
        if (dot(ns, ng) < 0.0f) ns = -ns;
        out.hit = hit;
        out.surface = surface;
        out.material = sample;
        out.double_sided = m.double_sided;
        out.alpha_mode = m.alpha_mode;
        out.front_face = front;
        out.facing_geometric = ng;
        out.facing_shading = ns;
        return true;
    }
    return false;
}

}  // namespace rf
