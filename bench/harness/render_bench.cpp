#include "render_bench.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>

#include <nlohmann/json.hpp>

#include "bench_report.h"
#include "bench_runner.h"
#include "core/parallel.h"
#include "rayforge/io/scene_io.h"
#include "ray_sets.h"
#include "rayforge/core/error.h"
#include "rayforge/world.h"

namespace rf::bench {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Replays recorded queries in chunks of consecutive rays (a tile's worth),
// each through the single-ray call the integrator made.
double replay_single(const Accel& accel, const std::vector<TracedRay>& rays, int threads) {
    volatile uint64_t sink = 0;
    const Clock::time_point start = Clock::now();
    parallel::with_threads(threads, [&] {
        parallel::for_range(size_t(0), rays.size(), size_t(4096), [&](size_t lo, size_t hi) {
            uint64_t found = 0;
            for (size_t i = lo; i < hi; ++i)
                found += rays[i].any_hit ? uint64_t(accel.occluded(rays[i].ray)) : uint64_t(accel.intersect(rays[i].ray).found());
            sink = sink + found;
        });
    });
    return ms_since(start);
}

// The same queries split into closest-hit and any-hit batches.
double replay_batches(const Accel& accel, const std::vector<Ray>& closest, const std::vector<Ray>& shadow,
                      int threads) {
    std::vector<Hit> hits(closest.size());
    std::vector<uint8_t> blocked(shadow.size());
    const Clock::time_point start = Clock::now();
    parallel::with_threads(threads, [&] {
        accel.intersect(closest, hits);
        accel.occluded(shadow, blocked);
    });
    return ms_since(start);
}

// The scene as rendered: a light at the view's light position when the
// spec asks for one and the scene has none, and the procedural sky when
// there is no environment (config.add_sky).
Scene lit_scene(const LoadedScene& loaded, const ViewSetup& view, bool add_sky) {
    Scene scene = loaded.scene;
    if (loaded.spec.has_light && scene.lights.empty()) {
        Light light;
        light.position = view.light;
        const float diagonal = length(loaded.geometry.bounds.extent());
        light.intensity = 0.25f * diagonal * diagonal;
        scene.lights.push_back(light);
    }
    const bool has_environment = scene.environment.texture >= 0 || max_component(scene.environment.color) > 0.0f;
    if (add_sky && !has_environment) {
        scene.textures.push_back(make_sky_texture());
        scene.environment.texture = int32_t(scene.textures.size() - 1);
        scene.environment.strength = 1.0f;
    }
    return scene;
}

RenderBenchRecord new_record(const LoadedScene& loaded, const std::string& integrator, const RenderBenchConfig& config) {
    RenderBenchRecord rec;
    rec.scene = loaded.spec.name;
    rec.integrator = integrator;
    rec.width = config.width;
    rec.height = config.height;
    rec.max_depth = config.max_depth;
    return rec;
}

// The index of the median of `values` (of the upper middle one for an even count).
size_t median_index(const std::vector<double>& values) {
    std::vector<size_t> order(values.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return values[a] < values[b]; });
    return order[order.size() / 2];
}

// One device row per GPU candidate: passes timed as the renderer reports them.
void gpu_rows(const LoadedScene& loaded, const Scene& scene, const ViewSetup& view, const std::string& integrator,
              const RenderOptions& base, const RenderBenchConfig& config, std::ostream& progress,
              std::vector<RenderBenchRecord>& records) {
    const Device device{Device::Kind::Cuda, config.gpu_device};
    const double pixels = double(config.width) * double(config.height);
    for (const GpuCandidate& candidate : config.gpu) {
        progress << "render bench: " << loaded.spec.name << ' ' << integrator << ' ' << config.width << 'x'
                 << config.height << " depth " << config.max_depth << " on " << to_string(device) << ' '
                 << candidate.label() << '\n';
        WorldOptions world_options;
        world_options.device = device;
        world_options.build = candidate.build.options;
        world_options.build.threads = config.threads;
        world_options.build.gpu_kernel = candidate.kernel;
        const std::unique_ptr<World> world = make_world(scene, world_options);
        const std::unique_ptr<Renderer> renderer = make_renderer(*world, view.camera, base);
        renderer->render_pass();  // warm-up
        std::vector<double> pass_ms, trace_ms;
        uint64_t rays = 0;
        for (int r = 0; r < config.repetitions; ++r) {
            renderer->render_pass();
            const PassStats& pass = renderer->last_pass();
            pass_ms.push_back(pass.pass_ms);
            if (pass.trace_ms >= 0.0) trace_ms.push_back(pass.trace_ms);
            rays += pass.closest_rays + pass.shadow_rays;
        }
        RenderBenchRecord rec = new_record(loaded, integrator, config);
        rec.accel = world->accel().stats().name;
        rec.device = to_string(device);
        rec.gpu = gpu_device_name(config.gpu_device);
        rec.pass_ms = median(pass_ms);
        rec.samples_per_s = pixels / (rec.pass_ms * 1e-3);
        rec.rays_per_sample = double(rays) / (pixels * double(config.repetitions));
        rec.rays_per_s = rec.samples_per_s * rec.rays_per_sample;
        rec.batch_trace_ms = std::nan("");
        // The pass whose time is the median (an even count: the upper one), with its own trace time.
        rec.trace_ms = trace_ms.size() == pass_ms.size() ? trace_ms[median_index(pass_ms)] : std::nan("");
        rec.trace_share = rec.trace_ms / rec.pass_ms;
        rec.shading_fraction = 1.0 - rec.trace_share;
        records.push_back(rec);
    }
}

// The CPU row: a recorded warm-up pass whose queries are replayed without shading.
RenderBenchRecord cpu_row(const LoadedScene& loaded, World& world, const ViewSetup& view, const std::string& integrator,
                          const RenderOptions& options, const RenderBenchConfig& config) {
    const std::unique_ptr<Renderer> renderer = make_renderer(world, view.camera, options);
    const Accel& accel = world.accel();
    std::vector<TracedRay> rays;
    renderer->render_pass_recorded(rays);
    std::vector<double> pass_ms, trace_ms, batch_ms;
    for (int r = 0; r < config.repetitions; ++r) {
        renderer->render_pass();
        pass_ms.push_back(renderer->last_pass().pass_ms);
    }
    const RenderStats stats = renderer->stats();
    for (int r = 0; r < config.repetitions; ++r) trace_ms.push_back(replay_single(accel, rays, config.threads));
    std::vector<Ray> closest, shadow;
    for (const TracedRay& t : rays) (t.any_hit ? shadow : closest).push_back(t.ray);
    for (int r = 0; r < config.repetitions; ++r) batch_ms.push_back(replay_batches(accel, closest, shadow, config.threads));
    const double pixels = double(config.width) * double(config.height);
    RenderBenchRecord rec = new_record(loaded, integrator, config);
    rec.accel = accel.stats().name;
    rec.threads = config.threads;
    rec.pass_ms = median(pass_ms);
    rec.samples_per_s = pixels / (rec.pass_ms * 1e-3);
    rec.rays_per_sample = double(stats.rays()) / double(stats.samples);
    rec.rays_per_s = rec.samples_per_s * rec.rays_per_sample;
    rec.trace_ms = median(trace_ms);
    rec.batch_trace_ms = median(batch_ms);
    rec.trace_share = rec.trace_ms / rec.pass_ms;
    rec.shading_fraction = 1.0 - rec.trace_share;
    return rec;
}

}  // namespace

std::vector<RenderBenchRecord> run_render_bench(const LoadedScene& loaded, const RenderBenchConfig& config,
                                                std::ostream& progress) {
    std::vector<RenderBenchRecord> records;
    const ViewSetup view = make_view_setup(loaded, 0, config.width, config.height);
    const Scene scene = lit_scene(loaded, view, config.add_sky);
    std::unique_ptr<World> world;
    if (config.cpu) {
        WorldOptions options;
        options.build = config.build;
        options.build.threads = config.threads;
        world = make_world(scene, options);
    }
    for (const std::string& integrator : config.integrators) {
        RenderOptions options;
        options.width = config.width;
        options.height = config.height;
        options.integrator = parse_integrator(integrator);
        options.max_depth = config.max_depth;
        options.threads = config.threads;
        options.spp = 1 << 20;
        gpu_rows(loaded, scene, view, integrator, options, config, progress, records);
        if (!config.cpu) continue;
        progress << "render bench: " << loaded.spec.name << ' ' << integrator << ' ' << config.width << 'x'
                 << config.height << " depth " << config.max_depth << '\n';
        records.push_back(cpu_row(loaded, *world, view, integrator, options, config));
    }
    return records;
}

void print_render_table(std::ostream& out, const std::vector<RenderBenchRecord>& records) {
    if (records.empty()) return;
    out << "\nrendering throughput (1 sample per pixel per pass; medians; trace: on the CPU the pass's own queries "
           "replayed without shading, on a device the path tracer's trace launches (extension + shadow) within the "
           "pass; trace share = trace / pass)\n";
    const auto ms = [](double value, const char* fmt) {
        char text[32];
        if (std::isnan(value)) return std::string("-");
        std::snprintf(text, sizeof text, fmt, value);
        return std::string(text);
    };
    char line[512];
    std::snprintf(line, sizeof line, "%-14s %-8s %-7s %-22s %-10s %5s %9s %10s %10s %9s %10s %10s %10s %12s %8s\n",
                  "scene", "integr.", "device", "accel", "res", "depth", "passes/s", "pass ms", "Msamp/s",
                  "rays/smp", "Mrays/s", "trace ms", "batch ms", "trace share", "shading");
    out << line;
    for (const RenderBenchRecord& r : records) {
        std::snprintf(line, sizeof line,
                      "%-14s %-8s %-7s %-22s %4dx%-5d %5d %9.2f %10.2f %10.3f %9.2f %10.2f %10s %10s %12s %8s\n",
                      r.scene.c_str(), r.integrator.c_str(), r.device.c_str(), r.accel.c_str(), r.width, r.height,
                      r.max_depth, r.pass_ms > 0.0 ? 1e3 / r.pass_ms : 0.0, r.pass_ms, r.samples_per_s * 1e-6,
                      r.rays_per_sample, r.rays_per_s * 1e-6, ms(r.trace_ms, "%.2f").c_str(),
                      ms(r.batch_trace_ms, "%.1f").c_str(), ms(100.0 * r.trace_share, "%.1f%%").c_str(),
                      ms(100.0 * r.shading_fraction, "%.1f%%").c_str());
        out << line;
    }
    for (const RenderBenchRecord& r : records) {
        if (r.gpu.empty()) continue;
        out << r.device << ": " << r.gpu << " (pass ms as the device renderer times a pass)\n";
        break;
    }
}

void write_render_json(const std::string& path, const std::vector<RenderBenchRecord>& records,
                       const std::string& command) {
    using Json = nlohmann::json;
    const MachineInfo machine = machine_info();
    const auto number = [](double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); };
    std::string gpu;
    for (const RenderBenchRecord& r : records)
        if (gpu.empty()) gpu = r.gpu;
    Json root;
    root["tool"] = "rayforge bench --integrator";
    root["rayforge_version"] = RAYFORGE_VERSION;
    root["date"] = iso_date_utc();
    root["command"] = command;
    root["machine"] = {{"cpu", machine.cpu}, {"cores", machine.cores}, {"gpu", gpu.empty() ? Json(nullptr) : Json(gpu)}};
    Json list = Json::array();
    for (const RenderBenchRecord& r : records)
        list.push_back({{"scene", r.scene},
                        {"integrator", r.integrator},
                        {"accel", r.accel},
                        {"device", r.device},
                        {"gpu", r.gpu.empty() ? Json(nullptr) : Json(r.gpu)},
                        {"view", r.view},
                        {"width", r.width},
                        {"height", r.height},
                        {"max_depth", r.max_depth},
                        {"threads", r.threads},
                        {"pass_ms", r.pass_ms},
                        {"passes_per_s", r.pass_ms > 0.0 ? Json(1e3 / r.pass_ms) : Json(nullptr)},
                        {"samples_per_s", r.samples_per_s},
                        {"rays_per_sample", r.rays_per_sample},
                        {"rays_per_s", r.rays_per_s},
                        {"trace_ms", number(r.trace_ms)},
                        {"batch_trace_ms", number(r.batch_trace_ms)},
                        {"trace_share", number(r.trace_share)},
                        {"shading_fraction", number(r.shading_fraction)}});
    root["records"] = list;
    std::ofstream out(path);
    if (!out) throw Error(path + ": cannot open for writing");
    out << root.dump(1) << '\n';
    if (!out) throw Error(path + ": write failed");
}

}  // namespace rf::bench
