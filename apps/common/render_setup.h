// What `rayforge render` and `rayforge view` share: the rendering options
// on the command line, parsed straight into the engine's own structs
// (RenderOptions, ToneMapping, WorldOptions, LoadOptions), and the command
// line's changes to a world before it renders (--time, lights, headlight),
// so both commands render the same image from the same arguments. What is
// kept here beyond those structs is what only a command line has: the
// scene and output names, the light and environment texts, and which
// options were given (they override the scene file's render settings).
#pragma once

#include <CLI/CLI.hpp>

#include <optional>
#include <string>
#include <vector>

#include "accel_options.h"
#include "device_options.h"
#include "paged_options.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/camera.h"
#include "rayforge/world.h"

namespace rf::cli {

struct RenderArgs {
    std::string scene;                 // a file or builtin:NAME (e.g. builtin:cornell)
    std::vector<std::string> outputs;  // render: one or more images; the format follows each extension
    RenderOptions render;              // --res, --spp, --integrator and the integrators' options, --threads, ...
    ToneMapping tone;                  // --exposure, --tonemap
    WorldOptions world;                // --device, the structure and update options, the paged caches' budgets
    LoadOptions load;                  // --animation
    std::optional<Camera> camera;      // --camera
    std::optional<float> time;         // --time
    // --light, --env, --env-map, --env-strength: applied to the world's scene (light intensities
    // and the environment map depend on it, so they stay text until then).
    std::vector<std::string> lights;
    std::string environment, environment_map;
    std::optional<float> environment_strength;
    bool no_headlight = false;
    // render only
    std::vector<std::string> aovs;     // albedo, normal, depth
    int save_every = 0;                // write the outputs every N passes (0 = only at the end)
    std::string frames;                // --frames FIRST:LAST[:STEP]
    bool quiet = false;
    CLI::App* command = nullptr;       // the command the options were parsed by
};

// The option groups; `spp_help` says what --spp means for the command.
void add_frame_options(CLI::App* cmd, RenderArgs& args, const std::string& spp_help);
void add_integrator_options(CLI::App* cmd, RenderArgs& args);
void add_tone_options(CLI::App* cmd, RenderArgs& args);
void add_light_options(CLI::App* cmd, RenderArgs& args);
// --device, --gpu-kernel, --build-on, --wavefront, --sort-rays.
void add_device_options(CLI::App* cmd, RenderArgs& args);
// --time, --animation and the structure's update options (--update ...).
void add_animation_options(CLI::App* cmd, RenderArgs& args);
// After parsing (add_frame_options registers it with the command): what
// depends on several options (--build-on needs a CUDA device, --aov turns
// the AOV films on, --threads everywhere).
void finish_render_args(RenderArgs& args);

// "640x480" -> (640, 480); false when malformed.
bool parse_resolution(const std::string& text, int& width, int& height);
// `count` comma-separated finite numbers; false when malformed.
bool parse_floats(const std::string& text, size_t count, std::vector<float>& out);

// The render options: a command-line option when given, else the scene
// file's setting, else the default.
RenderOptions render_options(const RenderArgs& args, const RenderSettings& file);
// --camera, else the world's own camera at its current time.
Camera initial_camera(const RenderArgs& args, const World& world);

// The command line's changes to a world before it renders: the world at
// --time; --light, --env, --env-map and --env-strength applied to an
// in-core world's scene (rf::Error for a paged world, whose lights are in
// its file); rf::Error when --animation names a clip of a scene without glTF clips.
void prepare_world(const RenderArgs& args, World& world);
// rf::Error when --light, --env, --env-map or --env-strength was given for a
// paged scene (its lights are in its file: they would be ignored).
void check_light_options(const RenderArgs& args, bool paged_scene);
// rf::Error when --animation `clip` was given for a scene without glTF clips (it would be ignored).
void check_animation_option(const std::string& clip, const Scene& scene);
// Nothing lights the world: no lights, a black environment, and no emitting
// triangle other than textured emission.
bool has_no_light(const World& world);
// A light at the camera when `integrator` uses lights and nothing lights an
// in-core world (unless --no-headlight); says so on stderr. True when one was added.
bool add_headlight_if_unlit(const RenderArgs& args, IntegratorKind integrator, const Camera& camera, World& world);

}  // namespace rf::cli
