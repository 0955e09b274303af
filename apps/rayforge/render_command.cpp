// `rayforge render SCENE -o OUT`: one path for every scene (a file, a
// built-in scene, a paged .rfpack) through rf::World: opened on the device,
// the command line's changes applied, rendered, written; one summary line on
// stdout, progress on stderr. --frames moves the world through time between
// images (its structure follows by the update method).
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "device_build_report.h"
#include "elapsed.h"
#include "progress_bar.h"
#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"
#include "render_setup.h"

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

// The scene, the outputs and the progressive loop.
void add_output_options(CLI::App* cmd, RenderArgs& a) {
    cmd->add_option("scene", a.scene,
                    "Scene file (.obj, .gltf, .glb, .ply, .aff, .json, .rfpack) or builtin:NAME")
        ->required();
    cmd->add_option("-o,--output", a.outputs,
                    "Output image; the format follows the extension: .png (tone-mapped 8-bit sRGB), .exr or "
                    ".pfm (linear float). Repeatable, e.g. -o out.png -o out.exr")
        ->required();
    cmd->add_option("--time-budget", a.render.time_budget_s,
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

std::string update_summary(const UpdateStats& u, const std::string& method) {
    char line[256];
    int n = std::snprintf(line, sizeof line, "update %.1f ms (%s, layout %.1f ms, SAH %.1f", u.update_ms,
                          method.c_str(), u.layout_ms, u.sah_cost);
    if (method == "adapt")
        n += std::snprintf(line + n, sizeof line - size_t(n), ", %llu rebuilt subtrees, %llu migrations",
                           (unsigned long long)u.rebuilt_subtrees, (unsigned long long)u.migrations);
    if (method == "two-level")
        n += std::snprintf(line + n, sizeof line - size_t(n), ", %llu meshes", (unsigned long long)u.meshes_updated);
    std::snprintf(line + n, sizeof line - size_t(n), ")");
    return line;
}

// "geometry 93.1% hit, 120 MiB read" for the progress bar and the summary.
std::string cache_line(const PagedScene& scene) {
    std::string line;
    for (const PageCacheReport& c : scene.caches()) {
        if (c.pages == 0) continue;
        char part[128];
        std::snprintf(part, sizeof(part), "%s%s %.1f%% hit, %s read", line.empty() ? "" : "; ", c.name.c_str(),
                      100.0 * c.hit_rate(), format_bytes(double(c.bytes_read)).c_str());
        line += part;
    }
    return line;
}

// A paged world's caches and query loops after the render.
void print_paged_summary(const RenderArgs& a, const World& world) {
    const PagedScene& scene = world.paged_scene();
    const PagedSceneInfo& info = scene.info();
    const PagedQueryStats q = scene.query_stats();
    const char* out = a.outputs.front().c_str();
    std::printf("%s: %llu query iterations | memory: caches %s of budget %s + always-resident levels %s\n", out,
                (unsigned long long)q.iterations,
                format_bytes(double(scene.memory_bytes() - std::min(scene.memory_bytes(), info.resident_bytes))).c_str(),
                format_bytes(double(a.world.paged.memory_budget)).c_str(),
                format_bytes(double(info.resident_bytes)).c_str());
    std::printf("%s: caches: %s\n", out, cache_line(scene).c_str());
    const double per_ray = q.queries ? 1.0 / double(q.queries) : 0.0;
    std::printf("%s: per query: %.2f iterations, %.1f grid cells, %.1f top-level nodes, %.2f pages searched, %.1f page nodes, "
                "%.1f quads tested | traversal %.1f ms, sort %.1f ms\n",
                out, double(q.ray_iterations) * per_ray, double(q.cells) * per_ray, double(q.middle_nodes) * per_ray,
                double(q.pages_searched) * per_ray, double(q.page_nodes) * per_ray, double(q.quads_tested) * per_ray,
                q.traversal_ms, q.sort_ms);
}

// The progress callback: the bar, with a paged world's cache line beside it.
ProgressCallback progress_of(const RenderArgs& a, ProgressBar& bar, const World& world) {
    if (a.quiet) return {};
    if (!world.paged()) return [&bar](double fraction) { bar.update(fraction); };
    return [&bar, &world](double fraction) {
        bar.set_note("  " + cache_line(world.paged_scene()));
        bar.update(fraction);
    };
}

// One image: the progressive loop with --save-every previews, the outputs, the summary.
void render_still(const RenderArgs& a, World& world, Renderer& renderer, double setup_ms) {
    const ToneMapping& tone = a.tone;
    {
        ProgressBar bar("render");
        PassCallback after_pass;
        if (a.save_every > 0)
            after_pass = [&](const Renderer& r) {
                if (r.passes() % a.save_every == 0 && r.passes() < r.options().spp) write_outputs(a, r, tone);
                return true;
            };
        render_progressive(renderer, after_pass, progress_of(a, bar, world));
    }
    write_outputs(a, renderer, tone);
    const WorldStats ws = world.stats();
    const RenderOptions& o = renderer.options();
    const RenderStats rs = renderer.stats();
    const double render_ms = rs.seconds * 1e3;
    const std::string accel = ws.accel.name + " on " + to_string(world.device());
    std::printf("%s: %dx%d %s %d spp, %llu %striangles | load %.1f ms | build %.1f ms (%s) | setup %.1f ms | "
                "render %.1f ms (%.2f Msamples/s, %.2f Mrays/s, %.1f ms/pass)\n",
                a.outputs.front().c_str(), o.width, o.height, integrator_name(o.integrator).c_str(), renderer.passes(),
                (unsigned long long)ws.triangles, world.paged() ? "paged " : "", ws.load_ms,
                ws.last_commit == CommitKind::None ? 0.0 : ws.commit_ms, accel.c_str(), setup_ms, render_ms,
                render_ms > 0.0 ? double(rs.samples) / (render_ms * 1e3) : 0.0,
                render_ms > 0.0 ? double(rs.rays()) / (render_ms * 1e3) : 0.0,
                renderer.passes() ? render_ms / renderer.passes() : 0.0);
    if (world.paged()) print_paged_summary(a, world);
    const BuildReport report = world.accel().build_report();
    if (report.on_device || report.layout_ms > 0.0)  // the device's stages
        std::printf("%s: %s\n", accel.c_str(),
                    bench::format_device_build({report, ws.accel.node_count, ws.accel.sah_cost}).c_str());
}

// --frames: one image per frame, the world moved to each frame's time (its
// structure follows by the update method; the renderer follows the world).
void render_frames(const RenderArgs& a, World& world, Renderer& renderer) {
    if (!world.animated())
        std::fprintf(stderr, "rayforge: note: %s is not animated; every frame is the same\n", a.scene.c_str());
    const FrameRange range = parse_frames(a.frames);
    const bool several = range.count() > 1;
    for (const std::string& output : a.outputs) (void)frame_path(output, range.first, several);  // fail fast
    const TimeRange time = world.time_range();
    const bool camera_follows = !a.camera && world.scene().animation.camera.has_value();
    const WorldStats initial = world.stats();
    const std::string& method = initial.update_method;
    std::printf("%s: %d frames, %llu triangles, %s, initial build %.1f ms\n", a.scene.c_str(), range.count(),
                (unsigned long long)initial.triangles, initial.accel.name.c_str(), initial.commit_ms);
    double update_total = 0.0, render_total = 0.0;
    for (int k = 0; k < range.count(); ++k) {
        const int frame = range.frame(k);
        const float t = time.frame_time(frame);
        const UpdateStats u = world.set_time(t);
        if (camera_follows) renderer.set_camera(world.camera());
        const Clock::time_point render_start = Clock::now();
        render_progressive(renderer, {}, {});
        const double render_ms = ms_since(render_start);
        for (const std::string& output : a.outputs)
            write_image(frame_path(output, frame, several), renderer.image(), a.tone);
        if (k > 0) update_total += u.update_ms;
        render_total += render_ms;
        if (!a.quiet)
            std::printf("  frame %d (t = %.3f s): %s | render %.1f ms\n", frame, double(t),
                        k == 0 ? "built" : update_summary(u, method).c_str(), render_ms);
    }
    if (range.last >= time.frame_count())
        std::fprintf(stderr, "rayforge: note: the animation has %d frames; later ones show its last pose\n",
                     time.frame_count());
    std::printf("%s: %d frames | update %.1f ms a frame | render %.1f ms a frame\n", a.outputs.front().c_str(),
                range.count(), range.count() > 1 ? update_total / (range.count() - 1) : 0.0,
                render_total / range.count());
}

}  // namespace

CLI::App* add_render_command(CLI::App& app, RenderArgs& a) {
    CLI::App* cmd = app.add_subcommand("render", "Render a scene to an image (.png, .exr or .pfm)");
    add_output_options(cmd, a);
    add_frame_options(cmd, a, "Samples per pixel = progressive passes (default 1)");
    add_integrator_options(cmd, a);
    add_tone_options(cmd, a);
    add_accel_options(cmd, a.world.build);
    add_light_options(cmd, a);
    add_device_options(cmd, a);
    add_paged_read_options(cmd, a.world.paged);
    add_animation_options(cmd, a);
    cmd->add_option("--frames", a.frames,
                    "Animated scenes: render frames FIRST:LAST[:STEP] (at the animation's frame rate) into outputs "
                    "named by a printf pattern, e.g. -o out_%04d.png; the structure is updated between frames "
                    "as --update says")
        ->group("Animation: acceleration-structure updates");
    cmd->add_flag("-q,--quiet", a.quiet, "No progress bar");
    return cmd;
}

// One path for every scene: a world opened (a file, a built-in scene or a
// paged file) on the device, the command line's changes applied, one
// renderer; --frames moves the world through time between images.
int run_render(const RenderArgs& a) {
    require_usable(a.world.device);  // before the scene loads: fail fast, naming the option
    if (!a.frames.empty()) (void)parse_frames(a.frames);
    const std::unique_ptr<World> world = open_world(a.scene, a.world, a.load);
    if (!a.frames.empty()) {  // the first frame's time, before the structure is built
        const FrameRange range = parse_frames(a.frames);
        world->set_time(world->time_range().frame_time(range.first));
    }
    prepare_world(a, *world);
    const RenderOptions options = render_options(a, world->scene().render_settings);
    const Camera camera = initial_camera(a, *world);
    add_headlight_if_unlit(a, options.integrator, camera, *world);
    world->commit();
    for (const std::string& note : world->notes()) std::fprintf(stderr, "rayforge: note: %s\n", note.c_str());
    const Clock::time_point setup_start = Clock::now();
    const std::unique_ptr<Renderer> renderer = make_renderer(*world, camera, options);  // shading tables, films
    const double setup_ms = ms_since(setup_start);
    if (a.frames.empty()) render_still(a, *world, *renderer, setup_ms);
    else render_frames(a, *world, *renderer);
    return 0;
}

}  // namespace rf::cli
