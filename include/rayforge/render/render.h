// Rendering a scene through an acceleration structure, tile-parallel on the CPU.
#pragma once

#include <functional>
#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/render/image.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

enum class IntegratorKind : uint8_t { Normals, AmbientOcclusion, Whitted };

struct RenderOptions {
    int width = 640;
    int height = 480;
    int spp = 1;                 // samples per pixel (jittered; 1 = pixel centre)
    IntegratorKind integrator = IntegratorKind::Whitted;
    int threads = 0;             // 0 = all cores
    int max_depth = 5;           // whitted: reflection/refraction recursion limit
    float ao_radius = 0.0f;      // ao: 0 = 10% of the scene diagonal
    int ao_samples = 16;         // ao: rays per primary hit per sample
    uint32_t seed = 0;           // per-pixel random streams derive from it
};

// Called from one thread at a time with the fraction done (0..1).
using ProgressCallback = std::function<void(double fraction)>;

Image render(const Scene& scene, const SceneGeometry& geometry, const Accel& accel,
             const Camera& camera, const RenderOptions& options,
             const ProgressCallback& progress = {});

IntegratorKind parse_integrator(const std::string& name);  // normals | ao | whitted
std::string integrator_name(IntegratorKind kind);

}  // namespace rf
