// `rayforge view SCENE [render options]`: the interactive viewer
// (apps/viewer). The render options mean what they mean for `render`, so a
// view and a render of the same arguments show the same image; --spp is
// where accumulation stops (default 4096 passes). A paged scene file
// (.rfpack) opens, like any scene, as a world (with the page caches'
// budgets of --memory-budget etc.).
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

// Lights and the start camera of every world the viewer opens, and the
// first scene's render settings under the command line's. A paged world's
// lights are in its file: nothing is added to it.
viewer::PrepareScene scene_preparation(const ViewArgs& a) {
    return [&a](World& world, viewer::SceneData& data, bool first, viewer::ViewSettings& settings) {
        const RenderArgs& r = a.render;
        if (first) {
            settings.render = render_options(r, world.scene().render_settings);
            settings.render.spp = r.command->count("--spp") > 0 ? r.render.spp : kViewerPasses;
            prepare_world(r, world);  // --time, the command line's lights
            data.camera = r.camera ? *r.camera : world.camera();
        }
        if (world.paged()) return;
        if (data.source.light && has_no_light(world)) {  // the views.json light, as the bench uses
            Light light;
            light.position = *data.source.light;
            light.intensity = 0.25f * data.size * data.size;
            world.scene().lights.push_back(light);
            world.materials_changed();
        }
        // The integrator can change in the window, so an unlit scene gets its headlight whatever it is now.
        add_headlight_if_unlit(r, IntegratorKind::Path, data.camera, world);
    };
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
    add_accel_options(cmd, a.render.world.build);
    add_light_options(cmd, a.render);
    add_device_options(cmd, a.render);
    add_paged_read_options(cmd, a.render.world.paged);
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
    check_world_options(r.world, r.scene);  // what the world would refuse fails before a window opens
    check_light_options(r, is_paged_scene_file(r.scene));
    viewer::ViewerConfig config;
    config.launched = launch_time();
    config.scene = r.scene;
    config.scenes_dir = a.scenes_dir;
    config.settings.world = r.world;
    config.settings.render = r.render;
    config.settings.render.spp = r.command->count("--spp") > 0 ? r.render.spp : kViewerPasses;
    config.settings.tone = r.tone;
    config.settings.motion_divisor = a.motion_scale == "auto" ? 0 : std::stoi(a.motion_scale);
    config.prepare = scene_preparation(a);
    config.first_load = r.load;
    if (!a.script.empty()) config.script = viewer::load_script(a.script);  // a typo fails before anything opens
    config.script_timeout_s = a.script_timeout_s;
    if (!a.bookmarks.empty()) config.bookmarks = a.bookmarks;
    if (!a.window.empty()) parse_resolution(a.window, config.window_width, config.window_height);
    return viewer::run_viewer(config);
}

}  // namespace rf::cli
