#include "render_setup.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <type_traits>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"

namespace rf::cli {

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
    a.resolution_opt = cmd->add_option("--res", a.resolution, "Image size WxH (default 640x480)")
                           ->check(CLI::Validator(
                               [](std::string& s) {
                                   int w, h;
                                   return parse_resolution(s, w, h) ? std::string()
                                                                    : "expected WxH, e.g. 640x480, got '" + s + "'";
                               },
                               "WxH"));
    a.spp_opt = cmd->add_option("--spp", a.spp, spp_help)->check(CLI::Range(1, 1 << 20));
    a.integrator_opt = cmd->add_option("--integrator", a.integrator, "normals | ao | whitted | path (default whitted)")
                           ->check(CLI::IsMember({"normals", "ao", "whitted", "path"}));
    cmd->add_option("--camera", a.camera, "Camera override: ex,ey,ez,tx,ty,tz,ux,uy,uz,fov (fov in degrees)")
        ->check(CLI::Validator(
            [](std::string& s) {
                std::vector<float> v;
                return parse_floats(s, 10, v) ? std::string() : "expected 10 comma-separated numbers";
            },
            "EYE,TARGET,UP,FOV"));
    cmd->add_option("--threads", a.threads, "Worker threads (0 = all cores)")->check(CLI::NonNegativeNumber);
}

void add_animation_options(CLI::App* cmd, RenderArgs& a) {
    a.time_opt = cmd->add_option("--time", a.time,
                                 "Animated scenes: the scene at this time in seconds (default: the animation's start)")
                     ->check(CLI::Range(-1e6f, 1e6f))
                     ->group("Animation: acceleration-structure updates");
    cmd->add_option("--animation", a.animation,
                    "glTF scenes with several animations: the one that plays, by name or 0-based index "
                    "(default: the first)")
        ->group("Animation: acceleration-structure updates");
    add_update_options(cmd, a.accel);
}

LoadOptions scene_load_options(const RenderArgs& a) {
    LoadOptions options;
    options.animation = a.animation;
    return options;
}

void check_animation_option(const std::string& clip, const Scene& scene) {
    if (!clip.empty() && scene.animation.clips.empty())
        throw Error("--animation " + clip + ": " + scene.source +
                    " has no glTF animations to choose from (only glTF files hold several)");
}

float apply_time_option(const RenderArgs& a, Scene& scene) {
    const float t = a.time_opt && a.time_opt->count() ? a.time : scene.animation.start;
    if (scene.animated()) scene.set_time(t);
    return t;
}

void add_integrator_options(CLI::App* cmd, RenderArgs& a) {
    a.max_depth_opt = cmd->add_option("--max-depth", a.max_depth, "path: bounces after the camera ray (default 8)")
                          ->check(CLI::Range(0, 1024));
    a.rr_depth_opt =
        cmd->add_option("--rr-depth", a.rr_depth, "path: Russian roulette from this bounce on (default 3)")
            ->check(CLI::Range(0, 1024));
    a.light_sampling_opt =
        cmd->add_option("--light-sampling", a.light_sampling,
                        "path: mis (light and BSDF sampling combined, default) | nee (light sampling only) | bsdf")
            ->check(CLI::IsMember({"mis", "nee", "bsdf"}));
    cmd->add_option("--clamp", a.clamp, "path: clamp each sample's radiance to this (0 = off; biased)")
        ->check(CLI::NonNegativeNumber);
    a.reflection_depth_opt =
        cmd->add_option("--reflection-depth", a.reflection_depth, "whitted: reflections per path (default 1, as seed 001)")
            ->check(CLI::Range(0, 30));
    a.refraction_depth_opt =
        cmd->add_option("--refraction-depth", a.refraction_depth, "whitted: refractions per path (default 2, as seed 001)")
            ->check(CLI::Range(0, 30));
    a.shading_opt = cmd->add_option("--shading", a.shading, "whitted: lambert (default) | phong | blinn highlights")
                        ->check(CLI::IsMember({"lambert", "phong", "blinn"}));
    a.ao_radius_opt = cmd->add_option("--ao-radius", a.ao_radius, "ao: ray length (0 = 10% of the scene diagonal)")
                          ->check(CLI::NonNegativeNumber);
    cmd->add_option("--ao-samples", a.ao_samples, "ao: rays per sample (default 16)")->check(CLI::Range(1, 65536));
}

void add_tone_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("--exposure", a.exposure, "Linear scale applied before writing (default 1)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--tonemap", a.tonemap, "PNG tone curve: clamp (default) | reinhard | aces; EXR/PFM stay linear")
        ->check(CLI::IsMember({"clamp", "reinhard", "aces"}));
    cmd->add_option("--seed", a.seed, "Random seed (default 0)");
}

void add_light_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("--light", a.lights,
                     "Add a point light at x,y,z with optional intensity (W/sr; default: the squared scene "
                     "diagonal / 4); repeatable");
    cmd->add_option("--env", a.environment, "Constant environment radiance r,g,b (replaces the scene's)");
    cmd->add_option("--env-map", a.environment_map,
                    "Equirectangular environment image (.hdr, .exr, .png, ...) or builtin:sky (replaces the scene's)");
    a.environment_strength_opt =
        cmd->add_option("--env-strength", a.environment_strength, "Multiplies the environment's radiance")
            ->check(CLI::NonNegativeNumber);
    cmd->add_flag("--no-headlight", a.no_headlight,
                  "Do not add a light at the camera when a whitted or path render would have no light at all");
}

void add_device_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("--device", a.device, "Where to render: cpu (default), cuda (= cuda:0) or cuda:N")
        ->check(device_validator());
    cmd->add_option("--gpu-kernel", a.gpu_kernel,
                    "GPU traversal kernel with --device cuda: bvh2 | aila-laine | cwbvh | kd-short-stack | kd-restart | "
                    "grid | grid-proximity (default " + to_string(kDefaultGpuKernel) + "); the structure is built "
                    "with the --builder / --grid-res options")
        ->check(gpu_kernel_validator());
    add_build_on_option(cmd, a.build_on);
    cmd->add_flag("--wavefront", a.wavefront,
                  "path on the CPU: run the path tracer stage by stage over queues of paths (a wavefront, as the "
                  "GPU does; same image)");
    cmd->add_flag("--sort-rays", a.sort_rays,
                  "path on the CPU with --wavefront: sort the active rays by an origin/direction key before each "
                  "extension");
}

RenderOptions render_options(const RenderArgs& a, const RenderSettings& file, const Device& device) {
    auto pick = [](const CLI::Option* option, const auto& cli, const auto& from_file, const auto& fallback) {
        using T = std::decay_t<decltype(fallback)>;
        return option->count() > 0 ? T(cli) : T(from_file.value_or(fallback));
    };
    const RenderOptions defaults;
    RenderOptions options;
    options.device = device;
    options.width = file.width.value_or(defaults.width);
    options.height = file.height.value_or(defaults.height);
    if (a.resolution_opt->count() > 0) parse_resolution(a.resolution, options.width, options.height);
    options.spp = pick(a.spp_opt, a.spp, file.spp, defaults.spp);
    options.max_depth = pick(a.max_depth_opt, a.max_depth, file.max_depth, defaults.max_depth);
    options.rr_depth = pick(a.rr_depth_opt, a.rr_depth, file.rr_depth, defaults.rr_depth);
    options.reflection_depth = pick(a.reflection_depth_opt, a.reflection_depth, file.reflection_depth,
                                    defaults.reflection_depth);
    options.refraction_depth = pick(a.refraction_depth_opt, a.refraction_depth, file.refraction_depth,
                                    defaults.refraction_depth);
    options.ao_radius = pick(a.ao_radius_opt, a.ao_radius, file.ao_radius, defaults.ao_radius);
    options.integrator =
        parse_integrator(pick(a.integrator_opt, a.integrator, file.integrator, integrator_name(defaults.integrator)));
    options.light_sampling = parse_light_sampling(
        pick(a.light_sampling_opt, a.light_sampling, file.light_sampling, to_string(defaults.light_sampling)));
    options.whitted_shading =
        parse_whitted_shading(pick(a.shading_opt, a.shading, file.shading, to_string(defaults.whitted_shading)));
    options.max_sample_value = a.clamp;
    options.time_budget_s = a.time_budget_s;
    options.aovs = !a.aovs.empty();
    options.ao_samples = a.ao_samples;
    options.threads = a.threads;
    options.seed = a.seed;
    options.wavefront = a.wavefront;
    options.sort_rays = a.sort_rays;
    return options;
}

BuildOptions structure_options(const RenderArgs& a, const Device& device) {
    const GpuKernel kernel = a.gpu_kernel.empty() ? kDefaultGpuKernel : parse_gpu_kernel(a.gpu_kernel);
    BuildOptions build = to_build_options(a.accel, a.threads);
    build.device = device;
    build.gpu_kernel = kernel;
    build.build_on_device = parse_build_on(a.build_on, device.is_cuda());
    if (device.is_cuda() && a.accel.accel.empty()) build.structure = structure_of(kernel);
    return build;
}

ToneMapping tone_mapping(const RenderArgs& a) { return {.exposure = a.exposure, .curve = parse_tone_curve(a.tonemap)}; }

Camera initial_camera(const RenderArgs& a, const Scene& scene) {
    if (a.camera.empty()) return scene.camera_or_default();
    try {
        return parse_camera(a.camera);
    } catch (const Error&) {
        throw Error("--camera: expected ex,ey,ez,tx,ty,tz,ux,uy,uz,fov");
    }
}

bool has_no_light(const Scene& scene, const SceneGeometry& geometry) {
    const Environment& env = scene.environment;
    const bool env_emits = env.texture >= 0 || max_component(env.color) > 0.0f;
    if (!scene.lights.empty() || (env_emits && env.strength > 0.0f)) return false;
    for (uint32_t tri : geometry.emissive_triangles)
        if (scene.materials[geometry.material[tri]].emission_texture == kNoTexture) return false;
    return true;
}

void apply_light_options(const RenderArgs& a, Scene& scene, const SceneGeometry& geometry) {
    const float diagonal = length(geometry.bounds.extent());
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
    if (a.environment_strength_opt->count() > 0) scene.environment.strength = a.environment_strength;
}

// Many OBJ/PLY files carry no light; a black image helps nobody. A
// headlight lights a surface at the target distance with irradiance pi, so
// a white diffuse surface there renders at about 1.
bool add_headlight_if_unlit(const RenderArgs& a, IntegratorKind integrator, const Camera& camera, Scene& scene,
                            const SceneGeometry& geometry) {
    const bool lit_integrator = integrator == IntegratorKind::Whitted || integrator == IntegratorKind::Path;
    if (!lit_integrator || a.no_headlight || !has_no_light(scene, geometry)) return false;
    Light headlight;
    headlight.position = camera.eye;
    const float distance = length(camera.target - camera.eye);
    headlight.intensity = 3.14159265f * distance * distance;
    scene.lights.push_back(headlight);
    std::fprintf(stderr, "rayforge: note: the scene has no light; adding a headlight at the camera "
                         "(--light to place lights, --no-headlight to disable)\n");
    return true;
}

}  // namespace rf::cli
