// `rayforge render SCENE -o OUT`: load, build the acceleration structure,
// render, write; one summary line on stdout, progress on stderr. With
// `--device cuda` the structure and the renderer live on that device, with
// the same outputs, progress and budgets.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "commands.h"
#include "device_build_report.h"
#include "progress_bar.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cli {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// "640x480" -> (640, 480); false when malformed.
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

// Ten comma-separated finite numbers; false when malformed.
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

Camera parse_camera(const std::string& text) {
    std::vector<float> v;
    if (!parse_floats(text, 10, v)) throw Error("--camera: expected ex,ey,ez,tx,ty,tz,ux,uy,uz,fov");
    Camera c;
    c.eye = {v[0], v[1], v[2]};
    c.target = {v[3], v[4], v[5]};
    c.up = {v[6], v[7], v[8]};
    c.vfov_degrees = v[9];
    return c;
}

// Nothing lights the scene: no lights, a black environment, and no emitting
// triangle other than textured emission (glowing details such as displays,
// which light nothing around them).
bool has_no_light(const Scene& scene, const SceneGeometry& geometry) {
    const Environment& env = scene.environment;
    const bool env_emits = env.texture >= 0 || max_component(env.color) > 0.0f;
    if (!scene.lights.empty() || (env_emits && env.strength > 0.0f)) return false;
    for (uint32_t tri : geometry.emissive_triangles)
        if (scene.materials[geometry.material[tri]].emission_texture == kNoTexture) return false;
    return true;
}

// Point lights from --light and the environment from --env / --env-map.
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

// "out.png" + "albedo" -> "out.albedo.exr" (".pfm" when the main output is a PFM).
std::string aov_path(const std::string& output, const std::string& aov) {
    const size_t dot = output.find_last_of('.');
    const size_t slash = output.find_last_of('/');
    const bool has_extension = dot != std::string::npos && (slash == std::string::npos || dot > slash);
    const std::string stem = has_extension ? output.substr(0, dot) : output;
    const std::string extension = has_extension ? output.substr(dot) : "";
    const bool pfm = extension == ".pfm" || extension == ".PFM";
    return stem + "." + aov + (pfm ? ".pfm" : ".exr");
}

void write_outputs(const RenderArgs& a, const Renderer& renderer, const ToneMapping& tone) {
    const Image image = renderer.image();
    for (const std::string& output : a.outputs) {
        write_image(output, image, tone);
        for (const std::string& aov : a.aovs) {
            const Image layer = aov == "albedo" ? renderer.albedo() : aov == "normal" ? renderer.normal()
                                                                                        : renderer.depth();
            write_image(aov_path(output, aov), layer, 1.0f);
        }
    }
}

// The progressive loop: progress bar, --save-every previews, the final outputs.
void render_and_write(const RenderArgs& a, Renderer& renderer, const ToneMapping& tone) {
    {
        ProgressBar bar("render");
        ProgressCallback progress;
        if (!a.quiet) progress = [&bar](double fraction) { bar.update(fraction); };
        PassCallback after_pass;
        if (a.save_every > 0)
            after_pass = [&](const Renderer& r) {
                if (r.passes() % a.save_every == 0 && r.passes() < r.options().spp) write_outputs(a, r, tone);
                return true;
            };
        render_progressive(renderer, after_pass, progress);
    }
    write_outputs(a, renderer, tone);
}

}  // namespace

namespace {

// The scene, the outputs, the image and the progressive loop.
void add_image_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("scene", a.scene, "Scene file (.obj, .gltf, .glb, .ply, .aff, .json) or builtin:NAME")->required();
    cmd->add_option("-o,--output", a.outputs,
                    "Output image; the format follows the extension: .png (tone-mapped 8-bit sRGB), .exr or "
                    ".pfm (linear float). Repeatable, e.g. -o out.png -o out.exr")
        ->required();
    a.resolution_opt = cmd->add_option("--res", a.resolution, "Image size WxH (default 640x480)")
                           ->check(CLI::Validator(
                               [](std::string& s) {
                                   int w, h;
                                   return parse_resolution(s, w, h) ? std::string()
                                                                    : "expected WxH, e.g. 640x480, got '" + s + "'";
                               },
                               "WxH"));
    a.spp_opt = cmd->add_option("--spp", a.spp, "Samples per pixel = progressive passes (default 1)")
                    ->check(CLI::Range(1, 1 << 20));
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
    cmd->add_option("--time-budget", a.time_budget_s,
                    "Stop after the pass that ends past this many seconds (--spp is then a cap; default: none)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--save-every", a.save_every, "Also write the outputs every N passes (progressive preview)")
        ->check(CLI::NonNegativeNumber);
}

// Each integrator's parameters.
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

// How the outputs are written, and the random seed.
void add_output_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("--exposure", a.exposure, "Linear scale applied before writing (default 1)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--tonemap", a.tonemap, "PNG tone curve: clamp (default) | reinhard | aces; EXR/PFM stay linear")
        ->check(CLI::IsMember({"clamp", "reinhard", "aces"}));
    cmd->add_option("--aov", a.aovs,
                    "Also write first-hit AOVs for denoisers: albedo, normal, depth (comma list or repeated); "
                    "written next to each output as NAME.albedo.exr etc.")
        ->delimiter(',')
        ->check(CLI::IsMember({"albedo", "normal", "depth"}));
    cmd->add_option("--seed", a.seed, "Random seed (default 0)");
}

// Lights and environment added to (or replacing) the scene's.
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

// Where it renders, and how the path tracer is scheduled.
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
    cmd->add_flag("-q,--quiet", a.quiet, "No progress bar");
}

}  // namespace

CLI::App* add_render_command(CLI::App& app, RenderArgs& a) {
    CLI::App* cmd = app.add_subcommand("render", "Render a scene to an image (.png, .exr or .pfm)");
    add_image_options(cmd, a);
    add_integrator_options(cmd, a);
    add_output_options(cmd, a);
    add_accel_options(cmd, a.accel);
    add_light_options(cmd, a);
    add_device_options(cmd, a);
    return cmd;
}

namespace {

// The render options: a command-line option when given, else the scene
// file's setting, else the default.
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

// Many OBJ/PLY files carry no light; a black image helps nobody. A
// headlight lights a surface at the target distance with irradiance pi, so
// a white diffuse surface there renders at about 1.
void add_headlight_if_unlit(const RenderArgs& a, const RenderOptions& options, const Camera& camera, Scene& scene,
                            const SceneGeometry& geometry) {
    const bool lit_integrator = options.integrator == IntegratorKind::Whitted || options.integrator == IntegratorKind::Path;
    if (!lit_integrator || a.no_headlight || !has_no_light(scene, geometry)) return;
    Light headlight;
    headlight.position = camera.eye;
    const float distance = length(camera.target - camera.eye);
    headlight.intensity = 3.14159265f * distance * distance;
    scene.lights.push_back(headlight);
    std::fprintf(stderr, "rayforge: note: the scene has no light; adding a headlight at the camera "
                         "(--light to place lights, --no-headlight to disable)\n");
}

// The structure's options on the chosen device. On a CUDA device the kernel
// picks the structure unless --accel says which.
BuildOptions structure_options(const RenderArgs& a, const Device& device) {
    const GpuKernel kernel = a.gpu_kernel.empty() ? kDefaultGpuKernel : parse_gpu_kernel(a.gpu_kernel);
    BuildOptions build = to_build_options(a.accel, a.threads);
    build.device = device;
    build.gpu_kernel = kernel;
    build.build_on_device = parse_build_on(a.build_on, device.is_cuda());
    if (device.is_cuda() && a.accel.accel.empty()) build.structure = structure_of(kernel);
    return build;
}

}  // namespace

int run_render(const RenderArgs& a) {
    const Device device = parse_device(a.device);
    require_usable(device, "--device " + a.device);  // before the scene loads: fail fast
    const BuildOptions build = structure_options(a, device);
    Clock::time_point start = Clock::now();
    Scene scene = load_scene(a.scene);
    SceneGeometry geometry = SceneGeometry::build(scene);
    const double load_ms = ms_since(start);

    const RenderOptions options = render_options(a, scene.render_settings, device);
    const ToneMapping tone{.exposure = a.exposure, .curve = parse_tone_curve(a.tonemap)};
    const Camera camera = a.camera.empty() ? scene.camera_or_default() : parse_camera(a.camera);
    apply_light_options(a, scene, geometry);
    add_headlight_if_unlit(a, options, camera, scene, geometry);

    const std::unique_ptr<Accel> accel = build_accel(geometry, build);
    const AccelStats stats = accel->stats();
    const Clock::time_point setup_start = Clock::now();
    const std::unique_ptr<Renderer> renderer = make_renderer(scene, geometry, *accel, camera, options);
    const double setup_ms = ms_since(setup_start);
    render_and_write(a, *renderer, tone);

    const RenderStats rs = renderer->stats();
    const double render_ms = rs.seconds * 1e3;
    const std::string accel_name = device.is_cuda() ? to_string(device) + " " + stats.name : stats.name;
    std::printf("%s: %dx%d %s %d spp, %zu triangles | load %.1f ms | build %.1f ms (%s) | setup %.1f ms | render %.1f ms "
                "(%.2f Msamples/s, %.2f Mrays/s)\n",
                a.outputs.front().c_str(), options.width, options.height, integrator_name(options.integrator).c_str(),
                renderer->passes(), geometry.size(), load_ms, stats.build_ms, accel_name.c_str(), setup_ms, render_ms,
                render_ms > 0.0 ? double(rs.samples) / (render_ms * 1e3) : 0.0,
                render_ms > 0.0 ? double(rs.rays()) / (render_ms * 1e3) : 0.0);
    if (device.is_cuda())
        std::printf("%s: %s\n", accel_name.c_str(),
                    bench::format_device_build({accel->build_report(), stats.node_count, stats.sah_cost}).c_str());
    return 0;
}

}  // namespace rf::cli
