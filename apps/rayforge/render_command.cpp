// `rayforge render SCENE -o OUT`: load, build the acceleration structure,
// render, write; one summary line on stdout, progress on stderr. With
// `--device cuda` the structure and the renderer live on that device, with
// the same outputs, progress and budgets.
#include <cctype>
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
#include "elapsed.h"
#include "render_setup.h"
#include "device_build_report.h"
#include "progress_bar.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cli {
namespace {

using Clock = std::chrono::steady_clock;

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

// The scene, the outputs and the progressive loop.
void add_output_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("scene", a.scene,
                    "Scene file (.obj, .gltf, .glb, .ply, .aff, .json, .rfpack) or builtin:NAME")
        ->required();
    cmd->add_option("-o,--output", a.outputs,
                    "Output image; the format follows the extension: .png (tone-mapped 8-bit sRGB), .exr or "
                    ".pfm (linear float). Repeatable, e.g. -o out.png -o out.exr")
        ->required();
    cmd->add_option("--time-budget", a.time_budget_s,
                    "Stop after the pass that ends past this many seconds (--spp is then a cap; default: none)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--save-every", a.save_every, "Also write the outputs every N passes (progressive preview)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--aov", a.aovs,
                    "Also write first-hit AOVs for denoisers: albedo, normal, depth (comma list or repeated); "
                    "written next to each output as NAME.albedo.exr etc.")
        ->delimiter(',')
        ->check(CLI::IsMember({"albedo", "normal", "depth"}));
}

// --frames FIRST:LAST[:STEP] (frame numbers at the animation's frame rate; STEP may be negative).
struct FrameRange {
    int first = 0, last = 0, step = 1;
    [[nodiscard]] int count() const { return (last - first) / step + 1; }
    [[nodiscard]] int frame(int k) const { return first + k * step; }
};

FrameRange parse_frames(const std::string& text) {
    FrameRange r;
    char extra = 0;
    const int n = std::sscanf(text.c_str(), "%d:%d:%d%c", &r.first, &r.last, &r.step, &extra);
    if (n < 2 || n > 3 || r.first < 0 || r.last < 0 || r.step == 0 || (r.last - r.first) * r.step < 0)
        throw Error("--frames: expected FIRST:LAST[:STEP] with frame numbers >= 0 and a step towards LAST, got '" +
                    text + "'");
    if (n == 2) r.step = r.first <= r.last ? 1 : -1;
    return r;
}

// "out_%04d.png" with frame 7 -> "out_0007.png"; the one printf integer
// conversion (%d, %0Nd) is required when more than one frame is written.
std::string frame_path(const std::string& pattern, int frame, bool several) {
    const size_t pct = pattern.find('%');
    if (pct == std::string::npos) {
        if (several) throw Error("-o " + pattern + ": several frames need a frame number pattern, e.g. out_%04d.png");
        return pattern;
    }
    size_t end = pct + 1;
    while (end < pattern.size() && std::isdigit(static_cast<unsigned char>(pattern[end]))) ++end;
    if (end >= pattern.size() || pattern[end] != 'd' || pattern.find('%', end) != std::string::npos)
        throw Error("-o " + pattern + ": the frame number pattern must be one %d or %0Nd");
    char number[32];
    std::snprintf(number, sizeof number, pattern.substr(pct, end + 1 - pct).c_str(), frame);
    return pattern.substr(0, pct) + number + pattern.substr(end + 1);
}

std::string update_summary(const UpdateStats& u, UpdateMethod method) {
    char line[256];
    int n = std::snprintf(line, sizeof line, "update %.1f ms (%s, layout %.1f ms, SAH %.1f", u.update_ms,
                          to_string(method).c_str(), u.layout_ms, u.sah_cost);
    if (method == UpdateMethod::Adapt)
        n += std::snprintf(line + n, sizeof line - size_t(n), ", %llu rebuilt subtrees, %llu migrations",
                           (unsigned long long)u.rebuilt_subtrees, (unsigned long long)u.migrations);
    if (method == UpdateMethod::TwoLevel)
        n += std::snprintf(line + n, sizeof line - size_t(n), ", %llu meshes", (unsigned long long)u.meshes_updated);
    std::snprintf(line + n, sizeof line - size_t(n), ")");
    return line;
}

// --frames: one image per frame, the structure updated between frames (on a
// CUDA device rebuilt there, with a new renderer).
int run_render_frames(const RenderArgs& a, const Device& device, BuildOptions build) {
    Scene scene = load_scene(a.scene, scene_load_options(a));
    check_animation_option(a.animation, scene);
    if (!scene.animated()) std::fprintf(stderr, "rayforge: note: %s is not animated; every frame is the same\n",
                                        a.scene.c_str());
    const FrameRange range = parse_frames(a.frames);
    const bool several = range.count() > 1;
    for (const std::string& output : a.outputs) (void)frame_path(output, range.first, several);  // fail fast
    const UpdateOptions update = to_update_options(a.accel, scene.render_settings.update.value_or(""), device);

    scene.set_time(scene.animation.frame_time(range.first));
    SceneGeometry geometry = SceneGeometry::build(scene);
    const RenderOptions options = render_options(a, scene.render_settings, device);
    const ToneMapping tone = tone_mapping(a);
    const bool camera_follows = a.camera.empty() && scene.animation.camera.has_value();
    Camera camera = initial_camera(a, scene);
    apply_light_options(a, scene, geometry);
    add_headlight_if_unlit(a, options.integrator, camera, scene, geometry);

    const std::unique_ptr<DynamicAccel> accel = build_dynamic_accel(scene, geometry, build, update);
    std::unique_ptr<Renderer> renderer = make_renderer(scene, geometry, accel->current(), camera, options);
    std::printf("%s: %d frames, %zu triangles, %s, initial build %.1f ms\n", a.scene.c_str(), range.count(),
                geometry.size(), accel->stats().name.c_str(), accel->initial_build_ms());
    double update_total = 0.0, render_total = 0.0;
    for (int k = 0; k < range.count(); ++k) {
        const int frame = range.frame(k);
        const float t = scene.animation.frame_time(frame);
        UpdateStats u;
        if (k > 0) {
            const GeometryChange change = scene.set_time(t);
            geometry.update(scene, change);
            if (device.is_cuda()) renderer.reset();  // it is bound to the structure the update replaces
            u = accel->update(change);
            if (camera_follows) camera = scene.camera_or_default();
            if (device.is_cuda()) {  // the renderer binds to the structure the device rebuilt
                renderer = make_renderer(scene, geometry, accel->current(), camera, options);
            } else {
                renderer->geometry_changed(change);
                if (camera_follows) renderer->set_camera(camera);
            }
        }
        const Clock::time_point render_start = Clock::now();
        render_progressive(*renderer, {}, {});
        const double render_ms = ms_since(render_start);
        for (const std::string& output : a.outputs) write_image(frame_path(output, frame, several), renderer->image(), tone);
        update_total += u.update_ms;
        render_total += render_ms;
        if (!a.quiet)
            std::printf("  frame %d (t = %.3f s): %s | render %.1f ms\n", frame, double(t),
                        k == 0 ? "built" : update_summary(u, accel->method()).c_str(), render_ms);
    }
    if (range.last >= scene.animation.frame_count())
        std::fprintf(stderr, "rayforge: note: the animation has %d frames; later ones show its last pose\n",
                     scene.animation.frame_count());
    std::printf("%s: %d frames | update %.1f ms a frame | render %.1f ms a frame\n", a.outputs.front().c_str(),
                range.count(), range.count() > 1 ? update_total / (range.count() - 1) : 0.0,
                render_total / range.count());
    return 0;
}

}  // namespace

CLI::App* add_render_command(CLI::App& app, RenderArgs& a) {
    CLI::App* cmd = app.add_subcommand("render", "Render a scene to an image (.png, .exr or .pfm)");
    add_output_options(cmd, a);
    add_frame_options(cmd, a, "Samples per pixel = progressive passes (default 1)");
    add_integrator_options(cmd, a);
    add_tone_options(cmd, a);
    add_accel_options(cmd, a.accel);
    add_light_options(cmd, a);
    add_device_options(cmd, a);
    add_paged_read_options(cmd, a.paged);
    add_animation_options(cmd, a);
    cmd->add_option("--frames", a.frames,
                    "Animated scenes: render frames FIRST:LAST[:STEP] (at the animation's frame rate) into outputs "
                    "named by a printf pattern, e.g. -o out_%04d.png; the structure is updated between frames "
                    "as --update says")
        ->group("Animation: acceleration-structure updates");
    cmd->add_flag("-q,--quiet", a.quiet, "No progress bar");
    return cmd;
}

int run_render(const RenderArgs& a) {
    if (is_paged_scene_file(a.scene)) return run_paged_render(a);
    const Device device = parse_device(a.device);
    require_usable(device, "--device " + a.device);  // before the scene loads: fail fast
    const BuildOptions build = structure_options(a, device);
    (void)to_update_options(a.accel, "", device);  // names, ranges and the device checked before the scene loads
    if (!a.frames.empty()) return run_render_frames(a, device, build);
    Clock::time_point start = Clock::now();
    Scene scene = load_scene(a.scene, scene_load_options(a));
    check_animation_option(a.animation, scene);
    apply_time_option(a, scene);
    SceneGeometry geometry = SceneGeometry::build(scene);
    const double load_ms = ms_since(start);

    const RenderOptions options = render_options(a, scene.render_settings, device);
    const ToneMapping tone = tone_mapping(a);
    const Camera camera = initial_camera(a, scene);
    apply_light_options(a, scene, geometry);
    add_headlight_if_unlit(a, options.integrator, camera, scene, geometry);

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
