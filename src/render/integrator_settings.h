// What every pass of a render reads, derived once from the options, the
// camera and the scene: the camera frame, each integrator's settings, the
// film clamp and the box wavefront ray sorting quantises origins in. Plain
// data, built on the host and read by both backends' per-sample code.
#pragma once

#include <cstdint>

#include "rayforge/math/box.h"
#include "rayforge/render/integrators.h"
#include "rayforge/scene/camera.h"
#include "render/integrators/ao.h"
#include "render/integrators/path_stages.h"
#include "render/integrators/whitted.h"

namespace rf {

struct RenderOptions;
struct SceneView;

struct IntegratorSettings {
    IntegratorKind integrator = IntegratorKind::Whitted;
    int width = 0, height = 0;
    uint32_t seed = 0;
    bool centre = false;      // one sample at the pixel centre (Whitted, AO and normals at 1 spp)
    float clamp = 0.0f;       // > 0: each sample's radiance scaled down to at most this
    bool aovs = false;        // first-hit albedo, normal and depth films
    CameraFrame camera;
    PathSettings path;
    WhittedSettings whitted;
    AoSettings ao;
    bool sort_rays = false;   // wavefront: sort the active rays before each extension
    Box3f sort_bounds;        // the scene and the camera: where ray origins are quantised
};

IntegratorSettings make_integrator_settings(const RenderOptions& options, const Camera& camera, const SceneView& view,
                                            const Box3f& scene_bounds);

}  // namespace rf
