// `rayforge view SCENE [render options]`: the interactive viewer
// (apps/viewer). The render options mean what they mean for `render`, so a
// view and a render of the same arguments show the same image; --spp is
// where accumulation stops (default 4096 passes). A paged scene file
// (.rfpack) opens with the page caches' budgets of --memory-budget etc.
#include <cmath>
#include <cstdio>

#include "commands.h"
#include "rayforge/core/error.h"
#include "rayforge/ooc/paged_scene.h"
#include "script.h"
#include "viewer.h"

namespace rf::cli {
namespace {

constexpr int kViewerPasses = 4096;

// Lights and the start camera of every scene the viewer loads, and the
// first scene's render settings under the command line's. A paged scene
// has no render settings (its `scene` is empty, as `render` of one uses)
// and its lights are in its file: nothing is added to it.
auto scene_preparation(const ViewArgs& a, const Device& device) {
    return [&a, device](viewer::SceneData& data, bool first, viewer::ViewSettings& settings) {
        const RenderArgs& r = a.render;
        Scene& scene = data.scene;
        if (first) {
            const RenderOptions from_file = render_options(r, scene.render_settings, device);
            settings.render = from_file;
            settings.render.spp = r.spp_opt->count() > 0 ? r.spp : kViewerPasses;
            if (!r.camera.empty()) data.camera = initial_camera(r, scene);
            if (r.accel.update_method.empty() && scene.render_settings.update)
                settings.update.method = parse_update_method(*scene.render_settings.update);
        }
        if (data.paged) return;
        if (first && scene.animated() && r.time_opt->count() > 0) {  // the first scene at --time
            apply_time_option(r, scene);
            data.geometry = SceneGeometry::build(scene);
        }
        if (first) apply_light_options(r, scene, data.geometry);
        if (data.source.light && has_no_light(scene, data.geometry)) {  // the views.json light, as the bench uses
            Light light;
            light.position = *data.source.light;
            light.intensity = 0.25f * data.size * data.size;
            scene.lights.push_back(light);
        }
        // The integrator can change in the window, so an unlit scene gets its headlight whatever it is now.
        add_headlight_if_unlit(r, IntegratorKind::Path, data.camera, scene, data.geometry);
    };
}

// What `render` refuses for a paged scene file, refused before a window opens.
void check_paged_start(const RenderArgs& r, const Device& device) {
    if (device.is_cuda()) throw Error("paged scenes render on the CPU in this version (--device cpu)");
    if (!r.lights.empty() || !r.environment.empty() || !r.environment_map.empty())
        throw Error("--light, --env and --env-map are not applied to paged scenes (their lights are in the file)");
}

}  // namespace

CLI::App* add_view_command(CLI::App& app, ViewArgs& a) {
    CLI::App* cmd = app.add_subcommand(
        "view", "Open a scene in an interactive window: progressive rendering, camera controls, live settings");
    cmd->add_option("scene", a.render.scene,
                    "Scene file (.obj, .gltf, .glb, .ply, .aff, .json, .rfpack), builtin:NAME, or a name of "
                    "../shared/scenes/views.json (e.g. sponza)")
        ->required();
    add_frame_options(cmd, a.render, "Passes to accumulate while the camera rests, then stop (default 4096)");
    add_integrator_options(cmd, a.render);
    add_tone_options(cmd, a.render);
    add_accel_options(cmd, a.render.accel);
    add_light_options(cmd, a.render);
    add_device_options(cmd, a.render);
    add_paged_read_options(cmd, a.render.paged);
    add_animation_options(cmd, a.render);
    const std::string group = "Viewer";
    cmd->add_option("--script", a.script,
                    "Run the commands of FILE (one per line, docs/viewer.md), then exit: 0 when all succeeded")
        ->check(CLI::ExistingFile)
        ->group(group);
    cmd->add_option("--script-timeout", a.script_timeout_s, "The longest a script wait may take, in seconds (default 120)")
        ->check(CLI::Range(0.1, 86400.0))
        ->group(group);
    cmd->add_option("--bookmarks", a.bookmarks, "Camera bookmarks file (default rayforge-bookmarks.json)")->group(group);
    cmd->add_option("--window", a.window, "Window size WxH (default: the image size, enlarged while small)")
        ->check(CLI::Validator(
            [](std::string& s) {
                int w, h;
                return parse_resolution(s, w, h) ? std::string() : "expected WxH, got '" + s + "'";
            },
            "WxH"))
        ->group(group);
    cmd->add_option("--motion-scale", a.motion_scale,
                    "While the camera moves, divide each side of the image by this: auto (a preview pass of about "
                    "30 ms) or 1..8 (default auto)")
        ->check(CLI::IsMember({"auto", "1", "2", "3", "4", "5", "6", "7", "8"}))
        ->group(group);
    cmd->add_option("--scenes-dir", a.scenes_dir, "Folder of views.json for the scene switcher (default: search)")
        ->group(group);
    return cmd;
}

int run_view(const ViewArgs& a) {
    const RenderArgs& r = a.render;
    const Device device = parse_device(r.device);
    if (is_paged_scene_file(r.scene)) check_paged_start(r, device);
    require_usable(device, "--device " + r.device);
    viewer::ViewerConfig config;
    config.launched = launch_time();
    config.scene = r.scene;
    config.scenes_dir = a.scenes_dir;
    config.settings.build = structure_options(r, device);
    config.settings.render = render_options(r, RenderSettings{}, device);
    config.settings.render.spp = r.spp_opt->count() > 0 ? r.spp : kViewerPasses;
    config.settings.tone = tone_mapping(r);
    config.settings.update = to_update_options(r.accel, "", device);
    config.settings.motion_divisor = a.motion_scale == "auto" ? 0 : std::stoi(a.motion_scale);
    config.prepare = scene_preparation(a, device);
    config.paged = paged_scene_options(r.paged, r.threads);
    config.first_load = scene_load_options(r);  // a malformed budget fails before the window opens
    if (!a.script.empty()) config.script = viewer::load_script(a.script);  // a typo fails before anything opens
    config.script_timeout_s = a.script_timeout_s;
    if (!a.bookmarks.empty()) config.bookmarks = a.bookmarks;
    if (!a.window.empty()) parse_resolution(a.window, config.window_width, config.window_height);
    return viewer::run_viewer(config);
}

}  // namespace rf::cli
