#include "render_setup.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include "option_binding.h"
#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"

namespace rf::cli {
namespace {

bool given(const RenderArgs& a, const char* option) { return a.command && a.command->count(option) > 0; }

// The scene file's setting where the command line gave none.
template <class T, class U>
void take_from_file(const RenderArgs& a, const char* option, T& field, const std::optional<U>& setting) {
    if (!given(a, option) && setting) field = T(*setting);
}
template <class T, class Parse>
void take_from_file(const RenderArgs& a, const char* option, T& field, const std::optional<std::string>& setting,
                    Parse parse) {
    if (!given(a, option) && setting) field = parse(*setting);
}

}  // namespace

bool parse_resolution(const std::string& text, int& width, int& height) {
    size_t x = text.find_first_of("xX");
    if (x == std::string::npos) return false;
    try {
        size_t used_w = 0, used_h = 0;
        std::string w = text.substr(0, x), h = text.substr(x + 1);
        width = std::stoi(w, &used_w);
        height = std::stoi(h, &used_h);
        return used_w == w.size() && used_h == h.size() && width > 0 && height > 0;
    } catch (const std::exception&) {
        return false;
    }
}

bool parse_floats(const std::string& text, size_t count, std::vector<float>& out) {
    out.clear();
    std::stringstream ss(text);
    std::string item;
    while (std::getline(ss, item, ',')) {
        try {
            size_t used = 0;
            float v = std::stof(item, &used);
            while (used < item.size() && item[used] == ' ') ++used;
            if (used != item.size() || !std::isfinite(v)) return false;
            out.push_back(v);
        } catch (const std::exception&) {
            return false;
        }
    }
    return out.size() == count;
}

void add_frame_options(CLI::App* cmd, RenderArgs& a, const std::string& spp_help) {
    a.command = cmd;
    cmd->final_callback([&a] { finish_render_args(a); });
    cmd->add_option_function<std::string>(
           "--res", [&a](const std::string& s) { parse_resolution(s, a.render.width, a.render.height); },
           "Image size WxH (default 640x480)")
        ->check(CLI::Validator(
            [](std::string& s) {
                int w, h;
                return parse_resolution(s, w, h) ? std::string() : "expected WxH, e.g. 640x480, got '" + s + "'";
            },
            "WxH"));
    cmd->add_option("--spp", a.render.spp, spp_help)->check(CLI::Range(1, 1 << 20));
    add_named_option(cmd, "--integrator", a.render.integrator, parse_integrator, {"normals", "ao", "whitted", "path"},
                     "normals | ao | whitted | path (default whitted)");
    cmd->add_option_function<std::string>(
           "--camera", [&a](const std::string& s) { a.camera = parse_camera(s); },
           "Camera override: ex,ey,ez,tx,ty,tz,ux,uy,uz,fov (fov in degrees)")
        ->check(CLI::Validator(
            [](std::string& s) {
                std::vector<float> v;
                return parse_floats(s, 10, v) ? std::string() : "expected 10 comma-separated numbers";
            },
            "EYE,TARGET,UP,FOV"));
    cmd->add_option("--threads", a.render.threads, "Worker threads (0 = all cores)")->check(CLI::NonNegativeNumber);
}

void add_animation_options(CLI::App* cmd, RenderArgs& a) {
    const std::string group = "Animation: acceleration-structure updates";
    cmd->add_option_function<float>(
           "--time", [&a](float t) { a.time = t; },
           "Animated scenes: the scene at this time in seconds (default: the animation's start)")
        ->check(CLI::Range(-1e6f, 1e6f))
        ->group(group);
    cmd->add_option("--animation", a.load.animation,
                    "glTF scenes with several animations: the one that plays, by name or 0-based index "
                    "(default: the first)")
        ->group(group);
    add_update_options(cmd, a.world.update);
}

void add_integrator_options(CLI::App* cmd, RenderArgs& a) {
    RenderOptions& o = a.render;
    cmd->add_option("--max-depth", o.max_depth, "path: bounces after the camera ray (default 8)")
        ->check(CLI::Range(0, 1024));
    cmd->add_option("--rr-depth", o.rr_depth, "path: Russian roulette from this bounce on (default 3)")
        ->check(CLI::Range(0, 1024));
    add_named_option(cmd, "--light-sampling", o.light_sampling, parse_light_sampling, {"mis", "nee", "bsdf"},
                     "path: mis (light and BSDF sampling combined, default) | nee (light sampling only) | bsdf");
    cmd->add_option("--clamp", o.max_sample_value, "path: clamp each sample's radiance to this (0 = off; biased)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--reflection-depth", o.reflection_depth,
                    "whitted: reflections per path (default 1, as Bogolepov et al.)")
        ->check(CLI::Range(0, 30));
    cmd->add_option("--refraction-depth", o.refraction_depth,
                    "whitted: refractions per path (default 2, as Bogolepov et al.)")
        ->check(CLI::Range(0, 30));
    add_named_option(cmd, "--shading", o.whitted_shading, parse_whitted_shading, {"lambert", "phong", "blinn"},
                     "whitted: lambert (default) | phong | blinn highlights");
    cmd->add_option("--ao-radius", o.ao_radius, "ao: ray length (0 = 10% of the scene diagonal)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--ao-samples", o.ao_samples, "ao: rays per sample (default 16)")->check(CLI::Range(1, 65536));
}

void add_tone_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("--exposure", a.tone.exposure, "Linear scale applied before writing (default 1)")
        ->check(CLI::NonNegativeNumber);
    add_named_option(cmd, "--tonemap", a.tone.curve, parse_tone_curve, {"clamp", "reinhard", "aces"},
                     "PNG tone curve: clamp (default) | reinhard | aces; EXR/PFM stay linear");
    cmd->add_option("--seed", a.render.seed, "Random seed (default 0)");
}

void add_light_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("--light", a.lights,
                    "Add a point light at x,y,z with optional intensity (W/sr; default: the squared scene "
                    "diagonal / 4); repeatable");
    cmd->add_option("--env", a.environment, "Constant environment radiance r,g,b (replaces the scene's)");
    cmd->add_option("--env-map", a.environment_map,
                    "Equirectangular environment image (.hdr, .exr, .png, ...) or builtin:sky (replaces the scene's)");
    cmd->add_option_function<float>("--env-strength", [&a](float s) { a.environment_strength = s; },
                                    "Multiplies the environment's radiance")
        ->check(CLI::NonNegativeNumber);
    cmd->add_flag("--no-headlight", a.no_headlight,
                  "Do not add a light at the camera when a whitted or path render would have no light at all");
}

void add_device_options(CLI::App* cmd, RenderArgs& a) {
    add_device_option(cmd, a.world.device, "Where to render: cpu (default), cuda (= cuda:0) or cuda:N");
    add_gpu_kernel_option(cmd, a.world.build);
    add_build_on_option(cmd, a.world.build.build_on_device);
    cmd->add_flag("--wavefront", a.render.wavefront,
                  "path on the CPU: run the path tracer stage by stage over queues of paths (a wavefront, as the "
                  "GPU does; same image)");
    cmd->add_flag("--sort-rays", a.render.sort_rays,
                  "path on the CPU with --wavefront: sort the active rays by an origin/direction key before each "
                  "extension");
}

void finish_render_args(RenderArgs& a) {
    check_build_on(a.command, a.world.device);
    a.render.aovs = !a.aovs.empty();
    a.world.build.threads = a.render.threads;
    a.world.paged.threads = a.render.threads;
}

RenderOptions render_options(const RenderArgs& a, const RenderSettings& file) {
    RenderOptions o = a.render;
    take_from_file(a, "--res", o.width, file.width);
    take_from_file(a, "--res", o.height, file.height);
    take_from_file(a, "--spp", o.spp, file.spp);
    take_from_file(a, "--max-depth", o.max_depth, file.max_depth);
    take_from_file(a, "--rr-depth", o.rr_depth, file.rr_depth);
    take_from_file(a, "--reflection-depth", o.reflection_depth, file.reflection_depth);
    take_from_file(a, "--refraction-depth", o.refraction_depth, file.refraction_depth);
    take_from_file(a, "--ao-radius", o.ao_radius, file.ao_radius);
    take_from_file(a, "--integrator", o.integrator, file.integrator, parse_integrator);
    take_from_file(a, "--light-sampling", o.light_sampling, file.light_sampling, parse_light_sampling);
    take_from_file(a, "--shading", o.whitted_shading, file.shading, parse_whitted_shading);
    return o;
}

Camera initial_camera(const RenderArgs& a, const World& world) { return a.camera ? *a.camera : world.camera(); }

bool has_no_light(const World& world) {
    const Scene& scene = world.scene();
    const Environment& env = scene.environment;
    const bool env_emits = env.texture >= 0 || max_component(env.color) > 0.0f;
    if (!scene.lights.empty() || (env_emits && env.strength > 0.0f)) return false;
    const SceneGeometry& geometry = world.geometry();
    for (uint32_t tri : geometry.emissive_triangles)
        if (scene.materials[geometry.material[tri]].emission_texture == kNoTexture) return false;
    return true;
}

namespace {

void apply_light_options(const RenderArgs& a, World& world) {
    Scene& scene = world.scene();
    const float diagonal = length(world.bounds().extent());
    for (const std::string& text : a.lights) {
        std::vector<float> v;
        if (!parse_floats(text, 3, v) && !parse_floats(text, 4, v))
            throw Error("--light: expected x,y,z or x,y,z,intensity, got '" + text + "'");
        Light light;
        light.position = {v[0], v[1], v[2]};
        light.intensity = v.size() == 4 ? v[3] : 0.25f * diagonal * diagonal;
        scene.lights.push_back(light);
    }
    if (!a.environment.empty()) {
        std::vector<float> v;
        if (!parse_floats(a.environment, 3, v) || v[0] < 0 || v[1] < 0 || v[2] < 0)
            throw Error("--env: expected r,g,b (non-negative), got '" + a.environment + "'");
        scene.environment.color = {v[0], v[1], v[2]};
        scene.environment.texture = -1;
        scene.environment.strength = 1.0f;
    }
    if (!a.environment_map.empty()) {
        Texture map = a.environment_map == "builtin:sky" ? make_sky_texture()
                                                         : load_texture(a.environment_map, TextureEncoding::Srgb8);
        map.wrap_s = TextureWrap::Repeat;
        map.wrap_t = TextureWrap::ClampToEdge;
        scene.textures.push_back(std::move(map));
        scene.environment.texture = int32_t(scene.textures.size() - 1);
        scene.environment.strength = 1.0f;
    }
    if (a.environment_strength) scene.environment.strength = *a.environment_strength;
    world.materials_changed();
}

}  // namespace

void check_animation_option(const std::string& clip, const Scene& scene) {
    if (!clip.empty() && scene.animation.clips.empty())
        throw Error("--animation " + clip + ": " + scene.source +
                    " has no glTF animations to choose from (only glTF files hold several)");
}

void check_light_options(const RenderArgs& a, bool paged_scene) {
    const bool lights = !a.lights.empty() || !a.environment.empty() || !a.environment_map.empty() ||
                        a.environment_strength.has_value();
    if (lights && paged_scene)
        throw Error("--light, --env, --env-map and --env-strength are not applied to paged scenes (their lights are "
                    "in the file)");
}

void prepare_world(const RenderArgs& a, World& world) {
    check_animation_option(a.load.animation, world.scene());
    check_light_options(a, world.paged());
    if (a.time) world.set_time(*a.time);
    if (!a.lights.empty() || !a.environment.empty() || !a.environment_map.empty() || a.environment_strength)
        apply_light_options(a, world);
}

// Many OBJ/PLY files carry no light; a black image helps nobody. A
// headlight lights a surface at the target distance with irradiance pi, so
// a white diffuse surface there renders at about 1. A paged world's lights
// are its file's.
bool add_headlight_if_unlit(const RenderArgs& a, IntegratorKind integrator, const Camera& camera, World& world) {
    const bool lit_integrator = integrator == IntegratorKind::Whitted || integrator == IntegratorKind::Path;
    if (!lit_integrator || a.no_headlight || world.paged() || !has_no_light(world)) return false;
    Light headlight;
    headlight.position = camera.eye;
    const float distance = length(camera.target - camera.eye);
    headlight.intensity = 3.14159265f * distance * distance;
    world.scene().lights.push_back(headlight);
    world.materials_changed();
    std::fprintf(stderr, "rayforge: note: the scene has no light; adding a headlight at the camera "
                         "(--light to place lights, --no-headlight to disable)\n");
    return true;
}

}  // namespace rf::cli
