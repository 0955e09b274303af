// Rendering a world (rayforge/world.h), on the device it lives on:
// one-shot (rf::render) or progressive (rf::Renderer, one sample per pixel
// per pass accumulated into float films, with a callback after each pass,
// and a camera, options or world that may change between passes).
// Renderers are made by rf::make_renderer(World&, ...).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/progress.h"
#include "rayforge/render/display.h"
#include "rayforge/render/image.h"
#include "rayforge/render/integrators.h"
#include "rayforge/render/tone_mapping.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

struct RenderOptions {
    int width = 640;
    int height = 480;
    int spp = 1;                 // samples per pixel = progressive passes (1 = pixel centre for whitted/normals)
    IntegratorKind integrator = IntegratorKind::Whitted;
    int threads = 0;             // 0 = all cores
    uint32_t seed = 0;           // per-pixel, per-sample random streams derive from it
    double time_budget_s = 0.0;  // > 0: stop after the first pass that ends past this many seconds (spp is then a cap)
    bool aovs = false;           // accumulate the albedo, normal and depth AOVs of the first hit

    // path
    int max_depth = 8;           // bounces after the camera ray (0 = emitters and environment seen directly)
    int rr_depth = 3;            // Russian roulette from this bounce on
    LightSampling light_sampling = LightSampling::Mis;
    float max_sample_value = 0.0f;  // > 0: clamp each sample's radiance to this (biased; removes fireflies)
    bool wavefront = false;      // CPU: run the path tracer stage by stage over queues of paths (same
                                 // image); a CUDA device always does
    bool sort_rays = false;      // wavefront: sort the active rays by origin/direction key before each extension

    // whitted
    int reflection_depth = 1;    // one reflection (Bogolepov et al.'s default)
    int refraction_depth = 2;    //   and two refractions
    WhittedShading whitted_shading = WhittedShading::Lambert;

    // ao
    float ao_radius = 0.0f;      // 0 = 10% of the scene diagonal
    int ao_samples = 16;         // rays per primary hit per sample
};

// Counts of what a render traced, summed over passes.
struct RenderStats {
    uint64_t samples = 0;        // camera samples (pixels x passes)
    uint64_t closest_rays = 0;   // closest-hit queries (camera, bounce, alpha-skip rays)
    uint64_t shadow_rays = 0;    // any-hit queries
    double seconds = 0.0;        // wall time inside render_pass
    [[nodiscard]] uint64_t rays() const { return closest_rays + shadow_rays; }
};

// One query made by a render, kept to replay the same rays without shading
// (the bench's measure of what shading and sampling cost).
struct TracedRay {
    Ray ray;
    bool any_hit = false;  // occlusion query (shadow ray) rather than closest hit
};

// The queues of one extension round of a wavefront path tracer (a bounce,
// or a pass through a blended surface).
struct WavefrontWave {
    uint64_t paths = 0;        // active paths extended
    uint64_t shadow_rays = 0;  // shadow connections made by shading them
};

// What the last pass did.
struct PassStats {
    double pass_ms = 0.0;               // wall time of the pass, device work included
    uint64_t closest_rays = 0, shadow_rays = 0;
    std::vector<WavefrontWave> waves;   // wavefront path tracing: index = extension round, 0 = camera rays
    double sort_ms = 0.0;               // wavefront ray sorting (sort_rays)
    // Device path tracing: the summed kernel time of the pass's trace
    // launches (extension and shadow connections), from CUDA events; so
    // trace_ms / pass_ms is the trace share of a pass. < 0: not measured
    // (the CPU renderers, and the device's one-kernel integrators).
    double trace_ms = -1.0;
};

// Progressive rendering of a world on its device: each pass adds one sample
// per pixel to float films (colour and, with options.aovs, the first-hit
// albedo, normal and depth); the image is their mean. Made by
// make_renderer(World&, ...). Each pass holds the world shared and starts
// by reading its structure and scene: after World::set_time,
// materials_changed or geometry_replaced the next pass rebuilds the shading
// tables and restarts accumulation. Both backends run the same per-sample
// code, so a CPU and a CUDA render of the same options agree (docs/gpu.md
// says how closely).
class Renderer {
public:
    virtual ~Renderer() = default;

    // Adds one sample per pixel (sample index = passes()); `progress` sees
    // the fraction of this pass. When `cancel` is given and another thread
    // sets it, the pass stops early (the CPU checks it between 16x16 tiles
    // and wavefront chunks, a CUDA device before each pass's launches),
    // accumulation restarts as after set_camera, and render_pass returns
    // false; it returns true for a finished pass. The flag is only read.
    virtual bool render_pass(const ProgressCallback& progress = {}, const std::atomic<bool>* cancel = nullptr) = 0;
    // render_pass that also returns every query the pass made (CPU only: a
    // CUDA renderer throws rf::Error).
    virtual void render_pass_recorded(std::vector<TracedRay>& rays) = 0;
    [[nodiscard]] virtual int passes() const = 0;
    [[nodiscard]] virtual const RenderOptions& options() const = 0;
    [[nodiscard]] virtual Device device() const = 0;  // its world's
    // Summed over the passes since the last restart.
    [[nodiscard]] virtual RenderStats stats() const = 0;
    [[nodiscard]] virtual const PassStats& last_pass() const = 0;

    // The mean of the passes so far (black before the first).
    [[nodiscard]] virtual Image image() const = 0;
    // First-hit AOVs (options.aovs): albedo, shading normal (world, components
    // in [-1, 1]), and the distance along the camera ray (0 on a miss, in all
    // three channels). Empty images when AOVs are off.
    [[nodiscard]] virtual Image albedo() const = 0;
    [[nodiscard]] virtual Image normal() const = 0;
    [[nodiscard]] virtual Image depth() const = 0;

    // A display image on this renderer's device (empty until update_display).
    [[nodiscard]] virtual std::unique_ptr<DisplayImage> make_display_image() const = 0;
    // The mean of the passes so far, tone-mapped to 8-bit sRGB exactly as a
    // PNG of image() written with `tone` (the device's sRGB encoding may
    // differ from the host's by one code), into `display` (resized to the
    // image; it must come from make_display_image of a renderer on the same
    // device). Call it from the thread that runs the passes.
    virtual void update_display(DisplayImage& display, const ToneMapping& tone) const = 0;

    // Each of these restarts accumulation (no passes, no stats, black films).
    // The camera moved:
    virtual void set_camera(const Camera& camera) = 0;
    // New options (integrator, depths, resolution, samples, seed, ...).
    // Throws rf::Error for invalid options.
    virtual void set_options(const RenderOptions& options) = 0;
};

// Called after each pass with the renderer; return false to stop early.
using PassCallback = std::function<bool(const Renderer& renderer)>;

// Runs passes until options.spp are done or options.time_budget_s is spent
// (or `after_pass` returns false); `progress` sees the fraction of the spp.
void render_progressive(Renderer& renderer, const PassCallback& after_pass = {},
                        const ProgressCallback& progress = {});

// Throws rf::Error naming the first option out of its range (sizes, spp,
// depths, budgets); every renderer, CPU or GPU, checks its options with it.
void validate_render_options(const RenderOptions& options);

}  // namespace rf
