// Rendering throughput for `rayforge bench --integrator path|whitted|...`:
// how fast the integrators turn rays into pixels, next to how fast the same
// rays are traced without any shading. A pass of the integrator is recorded
// (every closest-hit and any-hit query in the order each tile made it) and
// replayed through the same single-ray calls on the same threads, so the
// difference between the two times is what shading, sampling, texture
// filtering and light selection cost. On a CUDA device (rf::make_renderer
// with a CUDA device: a wavefront path tracer) a pass is timed as the
// renderer reports it; there is no replay there: the path tracer's trace
// time is the summed kernel time of its trace launches (extension and
// shadow connections, CUDA events; PassStats::trace_ms), so the trace share
// of a pass separates kernel gains from shading costs.
#pragma once

#include <ostream>
#include <string>
#include <vector>

#include "bench_scenes.h"
#include "gpu_candidates.h"
#include "rayforge/accel/accel.h"
#include "rayforge/render/render.h"

namespace rf::bench {

struct RenderBenchConfig {
    std::vector<std::string> integrators;  // normals | ao | whitted | path
    int width = 1024, height = 768;
    int max_depth = 4;                     // path bounces
    int repetitions = 5;                   // timed passes after one warm-up; medians reported
    int threads = 0;
    BuildOptions build;                    // the structure traced
    bool add_sky = true;                   // scenes without an environment get the procedural sky
    bool cpu = true;                       // render on the CPU (over `build`)
    std::vector<GpuCandidate> gpu;         // and on the device, once per kernel and build
    int gpu_device = 0;
};

struct RenderBenchRecord {
    std::string scene, integrator, accel;
    std::string device = "cpu";      // "cpu" or "cuda:N"
    std::string gpu;                 // the device's name
    int view = 0, width = 0, height = 0, max_depth = 0, threads = 0;
    double pass_ms = 0.0;            // median wall time of one pass (1 sample per pixel)
    double samples_per_s = 0.0;      // camera samples
    double rays_per_sample = 0.0;    // closest + any-hit queries per camera sample
    double rays_per_s = 0.0;         // all queries, all bounces
    // CPU: the recorded queries replayed; CUDA path tracing: the trace
    // launches' kernel time within the pass; NaN where not measured.
    double trace_ms = 0.0;           // median (CPU: single-ray calls, no shading)
    double batch_trace_ms = 0.0;     // CPU only, median: the same queries through the batch interface
    double trace_share = 0.0;        // trace_ms / pass_ms
    double shading_fraction = 0.0;   // 1 - trace_share
};

// Renders view 0 (or each of `views`) of `scene` with each integrator.
std::vector<RenderBenchRecord> run_render_bench(const LoadedScene& scene, const RenderBenchConfig& config,
                                                std::ostream& progress);
void print_render_table(std::ostream& out, const std::vector<RenderBenchRecord>& records);
// `--json` of the render bench: one record per (scene, integrator, device,
// structure); throws rf::Error when the file cannot be written.
void write_render_json(const std::string& path, const std::vector<RenderBenchRecord>& records,
                       const std::string& command);

}  // namespace rf::bench
