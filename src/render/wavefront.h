// Wavefront path tracing (Laine, Karras and Aila 2013, "Megakernels
// Considered Harmful: Wavefront Path Tracing on GPUs"), written once for
// both backends: a pass of the path tracer run stage by stage over queues of
// paths instead of path by path. All paths of a chunk are generated, then,
// while any is active: (optionally) the active queue is sorted by ray key
// (Garanzha and Loop 2010, ray_sort_key.h), every active ray is extended,
// every hit is shaded (making at most one shadow connection each), the
// surviving paths and the connections are compacted into queues, and the
// shadow rays are tested; finally each path's radiance goes to its pixel.
//
// The stages are those of integrators/path_stages.h, the ones the megakernel
// path_radiance runs, and each path sees the same numbers in the same order,
// so the image is the megakernel's whatever the order of the queues. What a
// backend supplies is scheduling only: how a stage's items are run (TBB
// tasks, or one kernel launch with one thread per item), how the queues are
// compacted and sorted, and whether extension starts with one batch query.
// The per-item steps below and the loop (run_wavefront) are shared.
#pragma once

#include <cstdint>
#include <vector>

#include "rayforge/core/host_device.h"
#include "core/assert.h"
#include "rayforge/render/render.h"
#include "render/integrator_settings.h"
#include "render/integrators/path_stages.h"
#include "render/pixel_sample.h"
#include "render/ray_sort_key.h"

namespace rf {

// The arrays one chunk of paths keeps between stages, as plain pointers
// (host vectors on the CPU, device buffers on the GPU). Arrays by path hold
// the paths; arrays by slot follow the active queue of the current round.
struct WavefrontQueues {
    PathState* paths = nullptr;           // by path
    FirstHitAovs* aovs = nullptr;         // by path; null without AOVs
    uint32_t* active = nullptr;           // this round's queue of path indices
    uint32_t* next_active = nullptr;      // the next round's, written by compaction
    uint32_t* keys = nullptr;             // by slot, when sorting
    PathHit* found = nullptr;             // by slot: what extension found
    ShadowConnection* shadows = nullptr;  // by slot
    uint8_t* has_shadow = nullptr;        // by slot
    uint8_t* goes_on = nullptr;           // by slot: the path survives shading
    uint32_t* shadow_slots = nullptr;     // the slots with a shadow connection, compacted
};

// Generate: path i of the chunk starting at `first_pixel` (pixel order).
RF_HDI void wavefront_generate(const IntegratorSettings& s, uint32_t sample, uint32_t first_pixel,
                               const WavefrontQueues& q, uint32_t i) {
    const uint32_t pixel = first_pixel + i;
    const int x = int(pixel % uint32_t(s.width)), y = int(pixel / uint32_t(s.width));
    q.paths[i] = generate_camera_path(s.camera, x, y, s.width, s.height, sample, s.seed, s.path);
    if (q.aovs) q.aovs[i] = FirstHitAovs{};
    q.active[i] = i;
}

// Sort keys of slot k: neighbours in a sorted queue start close and go the same way.
RF_HDI void wavefront_sort_key(const IntegratorSettings& s, const WavefrontQueues& q, uint32_t k) {
    q.keys[k] = ray_sort_key(q.paths[q.active[k]].ray, s.sort_bounds);
}

// Extend slot k, whole (closest hit and the walk past cut-outs)...
template <class Tracer, class View>
RF_HD void wavefront_extend(const Tracer& tracer, const View& view, const WavefrontQueues& q, uint32_t k) {
    q.found[k] = extend_path(tracer, view, q.paths[q.active[k]]);
}

// ... or from a closest hit already found (a batch query).
template <class Tracer, class View>
RF_HD void wavefront_complete_extension(const Tracer& tracer, const View& view, const WavefrontQueues& q, uint32_t k,
                                        const Hit& first_hit) {
    q.found[k] = complete_extension(tracer, view, q.paths[q.active[k]], first_hit);
}

// Shade slot k: emission, one light sample as a shadow connection, the next ray.
template <class View>
RF_HD void wavefront_shade(const View& view, const PathSettings& settings, const WavefrontQueues& q, uint32_t k) {
    const uint32_t path = q.active[k];
    bool has_shadow = false;
    ShadowConnection shadow;
    q.goes_on[k] = shade_path(view, settings, q.paths[path], q.found[k], q.aovs ? &q.aovs[path] : nullptr, shadow,
                              has_shadow)
                       ? 1
                       : 0;
    q.has_shadow[k] = has_shadow ? 1 : 0;
    if (has_shadow) {
        shadow.path = path;
        q.shadows[k] = shadow;
    }
}

// Connect shadow j: adds its contribution when its light is visible. Each
// path made at most one connection this round, so no other item writes the path.
template <class Tracer, class View>
RF_HD void wavefront_connect(const Tracer& tracer, const View& view, const WavefrontQueues& q, uint32_t j) {
    const ShadowConnection& shadow = q.shadows[q.shadow_slots[j]];
    if (connect_shadow(tracer, view, shadow)) q.paths[shadow.path].radiance += shadow.contribution;
}

// The shadow ray of shadow j, for a backend that tests them in one batch.
RF_HDI const Ray& wavefront_shadow_ray(const WavefrontQueues& q, uint32_t j) {
    return q.shadows[q.shadow_slots[j]].ray;
}

// Accumulate path i into its pixel: one sample per pixel, as the progressive renderer does.
RF_HDI void wavefront_accumulate(const WavefrontQueues& q, uint32_t i, float clamp, const Films& films) {
    const PathState& path = q.paths[i];
    films.color[path.pixel] += film_sample(path.radiance, clamp);
    if (!q.aovs) return;
    films.albedo[path.pixel] += q.aovs[i].albedo;
    films.normal[path.pixel] += q.aovs[i].normal;
    films.depth[path.pixel] += Vec3f(q.aovs[i].depth);
}

// What compaction found: the next round's active paths and this round's shadow connections.
struct WaveSizes {
    uint32_t active = 0;
    uint32_t shadows = 0;
};

// One chunk of `count` paths through every round. Backend:
//   generate(count)            wavefront_generate for every path
//   sort(active)               keys, then the active queue sorted by them (called when settings.sort_rays)
//   extend(active)             wavefront_extend (or a batch query and wavefront_complete_extension) per slot
//   shade(active)              wavefront_shade per slot
//   WaveSizes compact(active)  next_active <- the slots that go on, shadow_slots <- those with a connection
//   connect(shadows)           wavefront_connect per shadow (or a batch any-hit query)
//   swap_queues()              active <-> next_active
//   accumulate(count)          wavefront_accumulate for every path
// `waves` gets each round's sizes added (index = round).
template <class Backend>
void run_wavefront(Backend& backend, const IntegratorSettings& settings, uint32_t count,
                   std::vector<WavefrontWave>& waves) {
    backend.generate(count);
    uint32_t active = count;
    for (size_t round = 0; active > 0; ++round) {
        if (settings.sort_rays && active > 1) backend.sort(active);
        backend.extend(active);
        backend.shade(active);
        const WaveSizes next = backend.compact(active);
        RF_ASSERT(next.active <= active && next.shadows <= active, "compaction made a queue longer");
        if (waves.size() <= round) waves.resize(round + 1);
        waves[round].paths += active;
        waves[round].shadow_rays += next.shadows;
        if (next.shadows > 0) backend.connect(next.shadows);
        backend.swap_queues();
        active = next.active;
    }
    backend.accumulate(count);
}

}  // namespace rf
