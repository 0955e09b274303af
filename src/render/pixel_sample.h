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

// What one camera sample of one pixel found: its radiance and, when the
// settings ask for them, the first hit's AOVs.
struct PixelSample {
    Vec3f value;
    FirstHitAovs aovs;
};

// Sample `sample` of `pixel`. kWithPath: whether the path tracer runs here
// as a megakernel (the CPU) or never reaches this function (the GPU traces
// paths as a wavefront, so its pixel kernel leaves the path tracer's code out).
template <bool kWithPath, class Tracer, class View>
RF_HD PixelSample sample_pixel(const Tracer& tracer, const View& view, const IntegratorSettings& s, uint32_t sample,
                               uint32_t pixel) {
    RF_ASSERT(pixel < uint32_t(s.width) * uint32_t(s.height), "a pixel outside the image");
    const int x = int(pixel % uint32_t(s.width)), y = int(pixel / uint32_t(s.width));
    RandomStream rng(pixel, sample, s.seed);
    const Vec2f jitter = s.centre ? Vec2f{0.5f, 0.5f} : rng.next2();
    const Vec2f lens = rng.next2();
    const Ray ray = s.camera.generate(float(x) + jitter.x, float(y) + jitter.y, s.width, s.height, lens.x, lens.y);
    PixelSample out;
    bool aovs_found = false;
    switch (s.integrator) {
        case IntegratorKind::Normals: out.value = normals_radiance(tracer, view, ray); break;
        case IntegratorKind::AmbientOcclusion: out.value = ao_radiance(tracer, view, ray, rng, s.ao); break;
        case IntegratorKind::Path:
            if constexpr (kWithPath) {
                out.value = path_radiance(tracer, view, ray, rng, s.path, s.aovs ? &out.aovs : nullptr);
                aovs_found = true;
                break;
            }
            [[fallthrough]];
        case IntegratorKind::Whitted:
        default: out.value = whitted_radiance(tracer, view, ray, rng, s.whitted); break;
    }
    if (s.aovs && !aovs_found) out.aovs = first_hit_aovs(tracer, view, ray);
    return out;
}

// Adds a sample of `pixel` to `films`.
RF_HDI void add_to_films(const PixelSample& p, const IntegratorSettings& s, uint32_t pixel, const Films& films) {
    films.color[pixel] += film_sample(p.value, s.clamp);
    if (!s.aovs) return;
    films.albedo[pixel] += p.aovs.albedo;
    films.normal[pixel] += p.aovs.normal;
    films.depth[pixel] += Vec3f(p.aovs.depth);
}

// Adds sample `sample` of `pixel` to `films` (see sample_pixel).
template <bool kWithPath, class Tracer, class View>
RF_HD void add_pixel_sample(const Tracer& tracer, const View& view, const IntegratorSettings& s, uint32_t sample,
                            uint32_t pixel, const Films& films) {
    add_to_films(sample_pixel<kWithPath>(tracer, view, s, sample, pixel), s, pixel, films);
}

}  // namespace rf
