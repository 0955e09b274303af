// `rayforge render SCENE -o OUT`: load, build the acceleration structure,
// render, write; one summary line on stdout, progress on stderr.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include "commands.h"
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

// Point lights from --light and the environment from --env.
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
}

}  // namespace

CLI::App* add_render_command(CLI::App& app, RenderArgs& a) {
    CLI::App* cmd = app.add_subcommand("render", "Render a scene to an image (.png, .exr or .pfm)");
    cmd->add_option("scene", a.scene, "Scene file (.obj, .gltf, .glb, .ply, .json) or builtin:NAME")->required();
    cmd->add_option("-o,--output", a.output, "Output image; the format follows the extension (.png, .exr, .pfm)")
        ->required();
    a.resolution_opt = cmd->add_option("--res", a.resolution, "Image size WxH (default 640x480)")
                           ->check(CLI::Validator(
                               [](std::string& s) {
                                   int w, h;
                                   return parse_resolution(s, w, h) ? std::string()
                                                                    : "expected WxH, e.g. 640x480, got '" + s + "'";
                               },
                               "WxH"));
    a.spp_opt = cmd->add_option("--spp", a.spp, "Samples per pixel (default 1)")->check(CLI::PositiveNumber);
    a.integrator_opt = cmd->add_option("--integrator", a.integrator, "normals | ao | whitted (default whitted)")
                           ->check(CLI::IsMember({"normals", "ao", "whitted"}));
    cmd->add_option("--camera", a.camera, "Camera override: ex,ey,ez,tx,ty,tz,ux,uy,uz,fov (fov in degrees)")
        ->check(CLI::Validator(
            [](std::string& s) {
                std::vector<float> v;
                return parse_floats(s, 10, v) ? std::string() : "expected 10 comma-separated numbers";
            },
            "EYE,TARGET,UP,FOV"));
    cmd->add_option("--threads", a.threads, "Worker threads (0 = all cores)")->check(CLI::NonNegativeNumber);
    a.max_depth_opt = cmd->add_option("--max-depth", a.max_depth, "Whitted recursion limit (default 5)")
                          ->check(CLI::Range(0, 30));
    a.ao_radius_opt = cmd->add_option("--ao-radius", a.ao_radius, "AO ray length (0 = 10% of the scene diagonal)")
                          ->check(CLI::NonNegativeNumber);
    cmd->add_option("--ao-samples", a.ao_samples, "AO rays per sample (default 16)")->check(CLI::Range(1, 65536));
    cmd->add_option("--exposure", a.exposure, "Linear scale applied before writing (default 1)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--seed", a.seed, "Random seed (default 0)");
    add_accel_options(cmd, a.accel);
    cmd->add_option("--light", a.lights,
                     "Add a point light at x,y,z with optional intensity (W/sr; default: the squared scene "
                     "diagonal / 4); repeatable");
    cmd->add_option("--env", a.environment, "Constant environment radiance r,g,b (replaces the scene's)");
    cmd->add_flag("--no-headlight", a.no_headlight,
                  "Do not add a light at the camera when a whitted render would have no light at all");
    cmd->add_flag("-q,--quiet", a.quiet, "No progress bar");
    return cmd;
}

int run_render(const RenderArgs& a) {
    Clock::time_point start = Clock::now();
    Scene scene = load_scene(a.scene);
    SceneGeometry geometry = SceneGeometry::build(scene);
    double load_ms = ms_since(start);

    // Scene file settings first, then whatever the command line says.
    const RenderSettings& file = scene.render_settings;
    RenderOptions options;
    options.width = file.width.value_or(options.width);
    options.height = file.height.value_or(options.height);
    options.spp = file.spp.value_or(options.spp);
    options.max_depth = file.max_depth.value_or(options.max_depth);
    options.ao_radius = file.ao_radius.value_or(options.ao_radius);
    if (file.integrator) options.integrator = parse_integrator(*file.integrator);
    if (a.resolution_opt->count() > 0) parse_resolution(a.resolution, options.width, options.height);
    if (a.spp_opt->count() > 0) options.spp = a.spp;
    if (a.integrator_opt->count() > 0) options.integrator = parse_integrator(a.integrator);
    if (a.max_depth_opt->count() > 0) options.max_depth = a.max_depth;
    if (a.ao_radius_opt->count() > 0) options.ao_radius = a.ao_radius;
    options.ao_samples = a.ao_samples;
    options.threads = a.threads;
    options.seed = a.seed;
    Camera camera = a.camera.empty() ? scene.camera_or_default() : parse_camera(a.camera);
    apply_light_options(a, scene, geometry);
    if (options.integrator == IntegratorKind::Whitted && !a.no_headlight && has_no_light(scene, geometry)) {
        // Many OBJ/PLY files carry no light; a black image helps nobody. A
        // headlight lights a surface at the target distance with irradiance pi,
        // so a white diffuse surface there renders at about 1.
        Light headlight;
        headlight.position = camera.eye;
        const float distance = length(camera.target - camera.eye);
        headlight.intensity = 3.14159265f * distance * distance;
        scene.lights.push_back(headlight);
        std::fprintf(stderr, "rayforge: note: the scene has no light; adding a headlight at the camera "
                             "(--light to place lights, --no-headlight to disable)\n");
    }

    const BuildOptions build_options = to_build_options(a.accel, a.threads);
    std::unique_ptr<Accel> accel = build_accel(geometry, build_options);
    AccelStats stats = accel->stats();

    Image image;
    double render_ms = 0.0;
    {
        ProgressBar bar("render");
        ProgressCallback progress;
        if (!a.quiet) progress = [&bar](double fraction) { bar.update(fraction); };
        Clock::time_point render_start = Clock::now();
        image = render(scene, geometry, *accel, camera, options, progress);
        render_ms = ms_since(render_start);
    }
    write_image(a.output, image, a.exposure);

    double samples = double(options.width) * double(options.height) * double(options.spp);
    std::printf("%s: %dx%d %s %d spp, %zu triangles | load %.1f ms | build %.1f ms (%s) | render %.1f ms "
                "(%.2f Msamples/s)\n",
                a.output.c_str(), options.width, options.height, integrator_name(options.integrator).c_str(),
                options.spp, geometry.size(), load_ms, stats.build_ms, stats.name.c_str(), render_ms,
                render_ms > 0.0 ? samples / (render_ms * 1e3) : 0.0);
    return 0;
}

}  // namespace rf::cli
