#include "render/integrator_settings.h"

#include "rayforge/render/render.h"
#include "render/scene_view.h"
#include "render/texture_lod.h"

namespace rf {

IntegratorSettings make_integrator_settings(const RenderOptions& o, const Camera& camera, const SceneView& view,
                                            const Box3f& scene_bounds) {
    IntegratorSettings s;
    s.integrator = o.integrator;
    s.width = o.width;
    s.height = o.height;
    s.seed = o.seed;
    // One sample per pixel at the pixel centre keeps single-sample Whitted and
    // normals images free of jitter; the path tracer always jitters.
    s.centre = o.spp == 1 && o.integrator != IntegratorKind::Path;
    s.clamp = o.max_sample_value;
    s.aovs = o.aovs;
    s.camera = CameraFrame::make(camera, o.width, o.height);
    s.path.max_depth = o.max_depth;
    s.path.rr_depth = o.rr_depth;
    s.path.strategy = o.light_sampling;
    s.path.pixel_spread = pixel_spread_angle(camera.vfov_degrees * (kPi / 180.0f), o.height);
    s.whitted.reflection_depth = o.reflection_depth;
    s.whitted.refraction_depth = o.refraction_depth;
    s.whitted.shading = o.whitted_shading;
    s.ao = {.samples = o.ao_samples, .radius = o.ao_radius > 0.0f ? o.ao_radius : 0.1f * view.diagonal()};
    s.sort_rays = o.sort_rays;
    s.sort_bounds = scene_bounds;
    s.sort_bounds.extend(s.camera.eye);
    return s;
}

}  // namespace rf
