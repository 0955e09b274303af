#include "render_bench.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <iomanip>

#include "bench_runner.h"
#include "backend/cpu/parallel.h"
#include "gpu_bench.h"
#include "io/procedural_sky.h"
#include "ray_sets.h"
#include "rayforge/core/error.h"

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

}  // namespace

std::vector<RenderBenchRecord> run_render_bench(const LoadedScene& loaded, const RenderBenchConfig& config,
                                                std::ostream& progress) {
    std::vector<RenderBenchRecord> records;
    Scene scene = loaded.scene;  // lights and sky are added to a copy
    const ViewSetup view = make_view_setup(loaded, 0, config.width, config.height);
    if (loaded.spec.has_light && scene.lights.empty()) {
        Light light;
        light.position = view.light;
        const float diagonal = length(loaded.geometry.bounds.extent());
        light.intensity = 0.25f * diagonal * diagonal;
        scene.lights.push_back(light);
    }
    const bool has_environment = scene.environment.texture >= 0 || max_component(scene.environment.color) > 0.0f;
    if (config.add_sky && !has_environment) {
        scene.textures.push_back(make_sky_texture());
        scene.environment.texture = int32_t(scene.textures.size() - 1);
        scene.environment.strength = 1.0f;
    }

    std::unique_ptr<Accel> accel;
    std::string accel_name;
    if (config.cpu) {
        BuildOptions build = config.build;
        build.threads = config.threads;
        accel = build_accel(loaded.geometry, build);
        accel_name = accel->stats().name;
    }
    const double pixels = double(config.width) * double(config.height);
    const std::string gpu_device = "cuda:" + std::to_string(config.gpu_device);
    const std::string gpu_name = config.gpu.empty() ? std::string() : gpu_device_name(config.gpu_device);

    for (const std::string& integrator : config.integrators) {
        RenderOptions options;
        options.width = config.width;
        options.height = config.height;
        options.integrator = parse_integrator(integrator);
        options.max_depth = config.max_depth;
        options.threads = config.threads;
        options.spp = 1 << 20;
        for (const GpuCandidate& candidate : config.gpu) {
            progress << "render bench: " << loaded.spec.name << ' ' << integrator << ' ' << config.width << 'x'
                     << config.height << " depth " << config.max_depth << " on " << gpu_device << ' '
                     << candidate.label() << '\n';
            BuildOptions build = candidate.build.options;
            build.threads = config.threads;
            GpuRenderer renderer(scene, loaded.geometry, view.camera, options, candidate.kernel, build,
                                 config.gpu_device);
            renderer.render_pass();  // warm-up
            std::vector<double> pass_ms;
            uint64_t rays = 0;
            for (int r = 0; r < config.repetitions; ++r) {
                const GpuPass pass = renderer.render_pass();
                pass_ms.push_back(pass.pass_ms);
                rays += pass.closest_rays + pass.shadow_rays;
            }
            RenderBenchRecord rec;
            rec.scene = loaded.spec.name;
            rec.integrator = integrator;
            rec.accel = renderer.accel_stats().name;
            rec.device = gpu_device;
            rec.gpu = gpu_name;
            rec.width = config.width;
            rec.height = config.height;
            rec.max_depth = config.max_depth;
            rec.pass_ms = median(pass_ms);
            rec.samples_per_s = pixels / (rec.pass_ms * 1e-3);
            rec.rays_per_sample = double(rays) / (pixels * double(config.repetitions));
            rec.rays_per_s = rec.samples_per_s * rec.rays_per_sample;
            rec.trace_ms = rec.batch_trace_ms = rec.shading_fraction = std::nan("");
            records.push_back(rec);
        }
        if (!config.cpu) continue;
        progress << "render bench: " << loaded.spec.name << ' ' << integrator << ' ' << config.width << 'x'
                 << config.height << " depth " << config.max_depth << '\n';
        ProgressiveRenderer renderer(scene, loaded.geometry, *accel, view.camera, options);

        // Warm-up pass, recorded: its queries are replayed below.
        std::vector<TracedRay> rays;
        renderer.render_pass_recorded(rays);
        std::vector<double> pass_ms, trace_ms, batch_ms;
        for (int r = 0; r < config.repetitions; ++r) {
            const RenderStats before = renderer.stats();
            renderer.render_pass();
            pass_ms.push_back((renderer.stats().seconds - before.seconds) * 1e3);
        }
        const RenderStats stats = renderer.stats();
        for (int r = 0; r < config.repetitions; ++r) trace_ms.push_back(replay_single(*accel, rays, config.threads));
        {
            std::vector<Ray> closest, shadow;
            for (const TracedRay& t : rays) (t.any_hit ? shadow : closest).push_back(t.ray);
            for (int r = 0; r < config.repetitions; ++r)
                batch_ms.push_back(replay_batches(*accel, closest, shadow, config.threads));
        }
        RenderBenchRecord rec;
        rec.scene = loaded.spec.name;
        rec.integrator = integrator;
        rec.accel = accel_name;
        rec.width = config.width;
        rec.height = config.height;
        rec.max_depth = config.max_depth;
        rec.threads = config.threads;
        rec.pass_ms = median(pass_ms);
        rec.samples_per_s = pixels / (rec.pass_ms * 1e-3);
        rec.rays_per_sample = double(stats.rays()) / double(stats.samples);
        rec.rays_per_s = rec.samples_per_s * rec.rays_per_sample;
        rec.trace_ms = median(trace_ms);
        rec.batch_trace_ms = median(batch_ms);
        rec.shading_fraction = 1.0 - rec.trace_ms / rec.pass_ms;
        records.push_back(rec);
    }
    return records;
}

void print_render_table(std::ostream& out, const std::vector<RenderBenchRecord>& records) {
    if (records.empty()) return;
    out << "\nrendering throughput (1 sample per pixel per pass; medians; trace = the pass's own queries replayed "
           "without shading, CPU only)\n";
    const auto ms = [](double value, const char* fmt) {
        char text[32];
        if (std::isnan(value)) return std::string("-");
        std::snprintf(text, sizeof text, fmt, value);
        return std::string(text);
    };
    char line[512];
    std::snprintf(line, sizeof line, "%-14s %-8s %-7s %-22s %-10s %5s %9s %10s %10s %9s %10s %10s %10s %8s\n",
                  "scene", "integr.", "device", "accel", "res", "depth", "passes/s", "pass ms", "Msamp/s",
                  "rays/smp", "Mrays/s", "trace ms", "batch ms", "shading");
    out << line;
    for (const RenderBenchRecord& r : records) {
        std::snprintf(line, sizeof line, "%-14s %-8s %-7s %-22s %4dx%-5d %5d %9.2f %10.2f %10.3f %9.2f %10.2f %10s %10s %8s\n",
                      r.scene.c_str(), r.integrator.c_str(), r.device.c_str(), r.accel.c_str(), r.width, r.height,
                      r.max_depth, r.pass_ms > 0.0 ? 1e3 / r.pass_ms : 0.0, r.pass_ms, r.samples_per_s * 1e-6,
                      r.rays_per_sample, r.rays_per_s * 1e-6, ms(r.trace_ms, "%.1f").c_str(),
                      ms(r.batch_trace_ms, "%.1f").c_str(), ms(100.0 * r.shading_fraction, "%.1f%%").c_str());
        out << line;
    }
    for (const RenderBenchRecord& r : records) {
        if (r.gpu.empty()) continue;
        out << r.device << ": " << r.gpu << " (pass ms as the device renderer times a pass)\n";
        break;
    }
}

}  // namespace rf::bench
