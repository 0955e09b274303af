// One camera sample of one pixel, added to the films: the per-pixel work of
// the integrators that need no wavefront, written once for both backends.
// The CPU renderer runs it over 16x16 tiles (backend/cpu/cpu_renderer.cpp),
// the CUDA renderer one thread per pixel (backend/cuda/pixel_kernels.h).
// Each sample draws from its own counter-based stream keyed by (pixel,
// sample, seed), so an image depends on neither the schedule nor the device.
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"
#include "core/assert.h"
#include "render/integrator_settings.h"
#include "render/integrators/ao.h"
#include "render/integrators/normals.h"
#include "render/integrators/path.h"
#include "render/integrators/whitted.h"

namespace rf {

// Per-pixel sums a pass adds to; the AOV films are null when not wanted.
struct Films {
    Vec3f* color = nullptr;
    Vec3f* albedo = nullptr;
    Vec3f* normal = nullptr;
    Vec3f* depth = nullptr;
};

// Adds sample `sample` of `pixel` to `films`. kWithPath: whether the path
// tracer runs here as a megakernel (the CPU) or never reaches this function
// (the GPU traces paths as a wavefront, so its pixel kernel leaves the path
// tracer's code out).
template <bool kWithPath, class Tracer, class View>
RF_HD void add_pixel_sample(const Tracer& tracer, const View& view, const IntegratorSettings& s, uint32_t sample,
                            uint32_t pixel, const Films& films) {
    RF_ASSERT(pixel < uint32_t(s.width) * uint32_t(s.height), "a pixel outside the image");
    const int x = int(pixel % uint32_t(s.width)), y = int(pixel / uint32_t(s.width));
    RandomStream rng(pixel, sample, s.seed);
    const Vec2f jitter = s.centre ? Vec2f{0.5f, 0.5f} : rng.next2();
    const Vec2f lens = rng.next2();
    const Ray ray = s.camera.generate(float(x) + jitter.x, float(y) + jitter.y, s.width, s.height, lens.x, lens.y);
    FirstHitAovs aovs;
    bool aovs_found = false;
    Vec3f value;
    switch (s.integrator) {
        case IntegratorKind::Normals: value = normals_radiance(tracer, view, ray); break;
        case IntegratorKind::AmbientOcclusion: value = ao_radiance(tracer, view, ray, rng, s.ao); break;
        case IntegratorKind::Path:
            if constexpr (kWithPath) {
                value = path_radiance(tracer, view, ray, rng, s.path, s.aovs ? &aovs : nullptr);
                aovs_found = true;
                break;
            }
            [[fallthrough]];
        case IntegratorKind::Whitted:
        default: value = whitted_radiance(tracer, view, ray, rng, s.whitted); break;
    }
    films.color[pixel] += film_sample(value, s.clamp);
    if (!s.aovs) return;
    if (!aovs_found) aovs = first_hit_aovs(tracer, view, ray);
    films.albedo[pixel] += aovs.albedo;
    films.normal[pixel] += aovs.normal;
    films.depth[pixel] += Vec3f(aovs.depth);
}

}  // namespace rf
