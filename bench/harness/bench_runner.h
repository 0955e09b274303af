// Runs the benchmark protocol: per scene and view, ray sets are generated
// once; every candidate and every Embree quality is built (median of
// build_repetitions) and traces every set (one warm-up, then the median of
// repetitions); an untimed instrumented pass counts traversal work; hits are
// compared with Embree's. GPU rows (BenchConfig::gpu) trace their own sets,
// gpu_samples_per_pixel jittered camera rays per pixel so that a set fills
// the device, resident on the device; a figure is the median kernel time of
// repetitions launches after one warm-up, and hits are compared with the
// first candidate's on the CPU. GPU rows also trace primary-morton beside
// every primary set (with_morton_primaries) and carry the registers, local
// memory and occupancy of their kernel's launches (BenchRecord::kernel_resources).
#pragma once

#include <functional>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "bench_scenes.h"
#include "candidates.h"
#include "device_build_report.h"
#include "embree_peer.h"
#include "gpu_candidates.h"
#include "ray_sets.h"

namespace rf::bench {

struct Resolution {
    int width = 1024;
    int height = 768;
};

struct BenchConfig {
    std::vector<std::string> scenes;         // views.json names, files, builtin:NAME
    std::string scenes_dir;                  // folder of views.json ("" = none)
    std::vector<int> views;                  // view indices; empty = every view
    std::vector<Resolution> resolutions{Resolution{}};
    std::vector<RaySetKind> ray_sets{std::begin(kAllRaySets), std::end(kAllRaySets)};
    std::vector<Candidate> candidates;       // CPU rows; the first is also the reference of the GPU rows
    bool cpu = true;                         // false: the candidates are not traced (GPU rows only)
    std::vector<GpuCandidate> gpu;           // GPU rows; empty = none
    int gpu_device = 0;                      // CUDA device ordinal of the GPU rows
    int cpu_samples_per_pixel = 1;           // camera rays per pixel of the CPU rows' sets
    int gpu_samples_per_pixel = 4;           //   and of the GPU rows' (the protocol's GPU rule)
    std::vector<EmbreeQuality> embree;       // peer qualities; empty = no peer
    int threads = 0;                         // 0 = all cores
    int repetitions = 5;                     // timed traces (after one warm-up)
    int build_repetitions = 3;
    bool count_traversal = true;             // the instrumented pass
    bool skip_unloadable = false;            // report and skip scenes that fail to load
    bool progress = true;                    // progress lines on the log stream
};

// One Embree quality traced on the same rays as a record.
struct PeerFigures {
    EmbreeQuality quality = EmbreeQuality::Medium;
    double mrays_per_s = 0.0;
    double trace_ms = 0.0;
    double build_ms = 0.0;
    size_t bytes = 0;
    double agreement = 0.0;       // share of rays with the same hit/miss and primitive (any-hit: same answer)
    // Over rays where both hit the same primitive (the precision of t):
    // |t_ours - t_peer| / max(|t_ours|, |t_peer|). Rays that hit different
    // primitives count against `agreement` instead.
    double max_rel_t_diff = 0.0;
};

// Hits of a GPU row compared with the CPU reference's on the same rays.
struct ReferenceAgreement {
    std::string reference;        // label of the CPU structure
    double agreement = 0.0;       // as PeerFigures::agreement
    double max_rel_t_diff = 0.0;
};

// One (scene, view, resolution, device, candidate, ray set).
struct BenchRecord {
    std::string scene;
    size_t triangles = 0;
    double load_ms = 0.0;
    int view = 0;
    int width = 0, height = 0;
    std::string device = "cpu";          // "cpu" or "cuda:N"
    std::string gpu;                     // GPU rows: the device's name
    Candidate candidate;                 // GPU rows: layout = the kernel's name
    int samples_per_pixel = 1;           // camera rays per pixel of the set
    RaySetKind ray_set = RaySetKind::Primary;
    size_t rays = 0;
    double mrays_per_s = 0.0;
    double trace_ms = 0.0;               // median (GPU rows: kernel time of one launch)
    std::vector<double> trace_ms_runs;   // every timed run
    double build_ms = 0.0;               // median, layout conversion included
    std::vector<double> build_ms_runs;
    double layout_ms = 0.0;
    AccelStats stats;                    // of the last build
    size_t triangle_bytes = 0;
    size_t device_bytes = 0;             // GPU rows: everything the tracer holds on the device
    bool has_counts = false;
    double steps_per_ray = 0.0, prims_per_ray = 0.0, restarts_per_ray = 0.0;
    double fetches_per_ray = 0.0;        // BVH node fetches (0: the structure has no BVH nodes)
    std::vector<PeerFigures> embree;     // CPU rows
    std::optional<ReferenceAgreement> reference;  // GPU rows
    DeviceBuildSummary device_build;     // GPU rows: the stages of the median build (on_device: built there)
    // GPU rows: registers, local memory and occupancy of the kernel's trace
    // launches (closest and any hit; empty where the backend does not list them).
    std::vector<GpuKernelResources> kernel_resources;
    [[nodiscard]] bool is_gpu() const { return device != "cpu"; }
};

double median(std::vector<double> values);

// The ray sets of the GPU rows: `kinds` with primary-morton right after
// primary (unless named already), so every GPU primary figure has its
// Morton-ordered twin (the protocol's scanline order stays the headline).
std::vector<RaySetKind> with_morton_primaries(const std::vector<RaySetKind>& kinds);

// The name the driver gives CUDA device `device`, "" when it cannot be used.
std::string gpu_device_name(int device);

// Hit agreement between two closest-hit result arrays.
void compare_hits(const std::vector<Hit>& ours, const std::vector<Hit>& peer, double& agreement,
                  double& max_rel_t_diff);

// Calls on_scene with each scene's records as soon as that scene is done;
// returns all records. Progress goes to `log`.
std::vector<BenchRecord> run_bench(const BenchConfig& config, std::ostream& log,
                                   const std::function<void(const std::vector<BenchRecord>&)>& on_scene = {});

}  // namespace rf::bench
