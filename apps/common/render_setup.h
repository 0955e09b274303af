// What `rayforge render` and `rayforge view` share: the rendering options
// on the command line (image, integrators, output, lights, device), and
// their translation into the engine's RenderOptions, BuildOptions, camera
// and scene lights, so both commands render the same image from the same
// arguments.
#pragma once

#include <CLI/CLI.hpp>

#include "paged_options.h"

#include <string>
#include <vector>

#include "accel_options.h"
#include "device_options.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/camera.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cli {

struct RenderArgs {
    std::string scene;  // a file or builtin:NAME (e.g. builtin:cornell)
    std::vector<std::string> outputs;  // render: one or more images; the format follows each extension
    std::string resolution;   // "WxH"
    int spp = 1;
    std::string integrator;
    std::string camera;       // "ex,ey,ez,tx,ty,tz,ux,uy,uz,fov"
    int threads = 0;
    int max_depth = 8;
    int rr_depth = 3;
    std::string light_sampling = "mis";
    float clamp = 0.0f;
    int reflection_depth = 1;
    int refraction_depth = 2;
    std::string shading = "lambert";
    double time_budget_s = 0.0;
    int save_every = 0;       // write the outputs every N passes (0 = only at the end)
    float ao_radius = 0.0f;
    int ao_samples = 16;
    float exposure = 1.0f;
    std::string tonemap = "clamp";
    std::vector<std::string> aovs;    // albedo, normal, depth
    unsigned seed = 0;
    AccelArgs accel;
    std::vector<std::string> lights;  // "x,y,z[,intensity]" point lights added to the scene
    std::string environment;          // "r,g,b" constant environment radiance
    std::string environment_map;      // an equirectangular image, or builtin:sky
    float environment_strength = 1.0f;
    bool no_headlight = false;
    bool quiet = false;
    std::string device = "cpu";       // cpu | cuda | cuda:N
    std::string gpu_kernel;           // "" = rf::kDefaultGpuKernel
    std::string build_on;             // --build-on device|host ("" = device), with --device cuda
    bool wavefront = false;           // CPU path tracer: wavefront passes
    bool sort_rays = false;           // CPU wavefront: sort rays before tracing
    PagedReadArgs paged;              // paged scenes: the page caches' budgets
    // Animated scenes.
    float time = 0.0f;                // --time: the scene at this time (seconds)
    std::string animation;            // --animation: the glTF clip (name or index; "" = the first)
    std::string frames;               // render --frames FIRST:LAST[:STEP]
    CLI::Option* time_opt = nullptr;
    // Options whose presence overrides the scene file's render settings.
    CLI::Option* resolution_opt = nullptr;
    CLI::Option* spp_opt = nullptr;
    CLI::Option* integrator_opt = nullptr;
    CLI::Option* max_depth_opt = nullptr;
    CLI::Option* ao_radius_opt = nullptr;
    CLI::Option* environment_strength_opt = nullptr;
    CLI::Option* rr_depth_opt = nullptr;
    CLI::Option* light_sampling_opt = nullptr;
    CLI::Option* reflection_depth_opt = nullptr;
    CLI::Option* refraction_depth_opt = nullptr;
    CLI::Option* shading_opt = nullptr;
};

// The option groups; `spp_help` says what --spp means for the command.
void add_frame_options(CLI::App* cmd, RenderArgs& args, const std::string& spp_help);
void add_integrator_options(CLI::App* cmd, RenderArgs& args);
void add_tone_options(CLI::App* cmd, RenderArgs& args);
void add_light_options(CLI::App* cmd, RenderArgs& args);
void add_device_options(CLI::App* cmd, RenderArgs& args);
// --time and the structure's update options (--update ...).
void add_animation_options(CLI::App* cmd, RenderArgs& args);
// The scene at --time when given (no change otherwise); returns the time used.
float apply_time_option(const RenderArgs& args, Scene& scene);
// How the command line's scene loads (--animation).
LoadOptions scene_load_options(const RenderArgs& args);
// rf::Error when --animation `clip` was given for a scene without glTF clips (it would be ignored).
void check_animation_option(const std::string& clip, const Scene& scene);

// "640x480" -> (640, 480); false when malformed.
bool parse_resolution(const std::string& text, int& width, int& height);
// `count` comma-separated finite numbers; false when malformed.
bool parse_floats(const std::string& text, size_t count, std::vector<float>& out);

// The render options: a command-line option when given, else the scene
// file's setting, else the default.
RenderOptions render_options(const RenderArgs& args, const RenderSettings& file, const Device& device);
// The structure's options on the chosen device (on a CUDA device the GPU
// kernel picks the structure unless --accel says which).
BuildOptions structure_options(const RenderArgs& args, const Device& device);
ToneMapping tone_mapping(const RenderArgs& args);
// --camera, else the scene's own camera (or one framing its bounds).
Camera initial_camera(const RenderArgs& args, const Scene& scene);

// Point lights from --light and the environment from --env / --env-map.
void apply_light_options(const RenderArgs& args, Scene& scene, const SceneGeometry& geometry);
// Nothing lights the scene: no lights, a black environment, and no emitting
// triangle other than textured emission.
bool has_no_light(const Scene& scene, const SceneGeometry& geometry);
// A light at the camera when `integrator` uses lights and nothing lights the
// scene (unless --no-headlight); says so on stderr. True when one was added.
bool add_headlight_if_unlit(const RenderArgs& args, IntegratorKind integrator, const Camera& camera, Scene& scene,
                            const SceneGeometry& geometry);

}  // namespace rf::cli
