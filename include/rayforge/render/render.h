// Rendering a scene through an acceleration structure on the CPU: one-shot
// (rf::render) or progressive (rf::ProgressiveRenderer, one sample per pixel
// per pass accumulated into a float film, with a callback after each pass).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/render/image.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

enum class IntegratorKind : uint8_t { Normals, AmbientOcclusion, Whitted, Path };

// How the path tracer estimates direct light: both strategies combined by
// multiple importance sampling (the default), next-event estimation only, or
// BSDF sampling only (emitters found by chance). All three converge to the same image.
enum class LightSampling : uint8_t { Mis, Nee, Bsdf };

// Whitted's local shading: Lambert, or the seeds' Phong / Blinn-Phong highlights.
enum class WhittedShading : uint8_t { Lambert, Phong, Blinn };

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
    bool wavefront = false;      // run the path tracer stage by stage over queues of paths (same image)
    bool sort_rays = false;      // wavefront: sort the active rays by origin/direction key before each extension

    // whitted
    int reflection_depth = 1;    // seed 001's default: one reflection
    int refraction_depth = 2;    //   and two refractions
    WhittedShading whitted_shading = WhittedShading::Lambert;

    // ao
    float ao_radius = 0.0f;      // 0 = 10% of the scene diagonal
    int ao_samples = 16;         // rays per primary hit per sample
};

// Called from one thread at a time with the fraction done (0..1).
using ProgressCallback = std::function<void(double fraction)>;

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

class ProgressiveRenderer {
public:
    // Everything passed must outlive the renderer. Throws rf::Error for invalid options.
    ProgressiveRenderer(const Scene& scene, const SceneGeometry& geometry, const Accel& accel,
                        const Camera& camera, const RenderOptions& options);
    ~ProgressiveRenderer();
    ProgressiveRenderer(const ProgressiveRenderer&) = delete;
    ProgressiveRenderer& operator=(const ProgressiveRenderer&) = delete;

    // Adds one sample per pixel (sample index = passes()); `progress` sees the
    // fraction of this pass.
    void render_pass(const ProgressCallback& progress = {});
    // render_pass that also returns every query the pass made, tile by tile in
    // the order each tile made them.
    void render_pass_recorded(std::vector<TracedRay>& rays);
    [[nodiscard]] int passes() const;
    [[nodiscard]] const RenderOptions& options() const;
    [[nodiscard]] RenderStats stats() const;

    // The mean of the passes so far (black before the first).
    [[nodiscard]] Image image() const;
    // First-hit AOVs (options.aovs): albedo, shading normal (world, components
    // in [-1, 1]), and the distance along the camera ray (0 on a miss, in all
    // three channels). Empty images when AOVs are off.
    [[nodiscard]] Image albedo() const;
    [[nodiscard]] Image normal() const;
    [[nodiscard]] Image depth() const;

private:
    struct State;
    void run_pass(const ProgressCallback& progress, std::vector<std::vector<TracedRay>>* tile_logs);
    std::unique_ptr<State> state_;
};

// Called after each pass with the renderer; return false to stop early.
using PassCallback = std::function<bool(const ProgressiveRenderer& renderer)>;

// Runs passes until options.spp are done or options.time_budget_s is spent
// (or `after_pass` returns false); `progress` sees the fraction of the spp.
// Returns the mean image.
Image render(const Scene& scene, const SceneGeometry& geometry, const Accel& accel,
             const Camera& camera, const RenderOptions& options,
             const ProgressCallback& progress = {});
void render_progressive(ProgressiveRenderer& renderer, const PassCallback& after_pass = {},
                        const ProgressCallback& progress = {});

// Throws rf::Error naming the first option out of its range (sizes, spp,
// depths, budgets); every renderer, CPU or GPU, checks its options with it.
void validate_render_options(const RenderOptions& options);

// Names for the CLI and scene files; parse_* throw rf::Error when unknown.
IntegratorKind parse_integrator(const std::string& name);  // normals | ao | whitted | path
std::string integrator_name(IntegratorKind kind);
LightSampling parse_light_sampling(const std::string& name);  // mis | nee | bsdf
std::string to_string(LightSampling sampling);
WhittedShading parse_whitted_shading(const std::string& name);  // lambert | phong | blinn
std::string to_string(WhittedShading shading);

}  // namespace rf
