#include "bench_runner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <ostream>

#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf::bench {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// One warm-up run, then `repetitions` timed runs of `trace`.
template <class F>
std::vector<double> timed_runs(int repetitions, F&& trace) {
    trace();
    std::vector<double> runs;
    for (int r = 0; r < repetitions; ++r) {
        const auto start = Clock::now();
        trace();
        runs.push_back(ms_since(start));
    }
    return runs;
}

// The results of one tracer on one ray set: hits for closest-hit sets,
// occlusion flags for any-hit sets.
struct TraceResult {
    std::vector<Hit> hits;
    std::vector<uint8_t> occluded;
};

void agreement_any_hit(const std::vector<uint8_t>& ours, const std::vector<uint8_t>& peer, double& agreement) {
    size_t same = 0;
    for (size_t i = 0; i < ours.size(); ++i) same += (ours[i] != 0) == (peer[i] != 0) ? 1 : 0;
    agreement = ours.empty() ? 1.0 : double(same) / double(ours.size());
}

struct BuiltCandidate {
    Candidate candidate;
    std::unique_ptr<Accel> accel;
    std::vector<double> build_runs;
};

struct BuiltPeer {
    EmbreeQuality quality;
    std::unique_ptr<EmbreePeer> peer;
    std::vector<double> build_runs;
};

struct BuiltGpu {
    GpuCandidate candidate;
    std::unique_ptr<Accel> accel;    // on the CUDA device
    std::vector<double> build_runs;  // AccelStats::build_ms of each build
    DeviceBuildSummary median_build; // the stages of the build with the median build_ms
    std::vector<GpuKernelResources> kernel_resources;
};

// Per-ray traversal work of an instrumented pass, into `rec`.
void count_work(const Accel& accel, const RaySet& set, BenchRecord& rec) {
    TraversalTotals totals;
    if (accel.count_traversal(set.rays, is_any_hit(set.kind), totals) && totals.rays > 0) {
        rec.has_counts = true;
        rec.steps_per_ray = double(totals.steps) / double(totals.rays);
        rec.prims_per_ray = double(totals.prim_tests) / double(totals.rays);
        rec.restarts_per_ray = double(totals.restarts) / double(totals.rays);
        rec.fetches_per_ray = double(totals.node_fetches) / double(totals.rays);
    }
}

// What `accel` answers for every ray of `set`.
TraceResult answers_of(const Accel& accel, const RaySet& set) {
    TraceResult out;
    if (is_any_hit(set.kind)) {
        out.occluded.assign(set.rays.size(), 0);
        accel.occluded(set.rays, out.occluded);
    } else {
        out.hits.assign(set.rays.size(), Hit{});
        accel.intersect(set.rays, out.hits);
    }
    return out;
}

// The GPU rows of one ray set: rays resident on the device, the kernel time
// of one launch per run, hits compared with the CPU reference's.
void trace_gpu_rows(const RaySet& set, const Accel& reference, const std::string& reference_label,
                    std::vector<BuiltGpu>& gpus, const BenchConfig& config, const BenchRecord& prototype,
                    std::vector<BenchRecord>& records) {
    const bool any_hit = is_any_hit(set.kind);
    const size_t n = set.rays.size();
    const TraceResult expected = answers_of(reference, set);
    for (BuiltGpu& g : gpus) {
        BenchRecord rec = prototype;
        rec.candidate = g.candidate.build;
        TraceResult out;  // what the last timed launch found
        out.hits.assign(any_hit ? 0 : n, Hit{});
        out.occluded.assign(any_hit ? n : 0, 0);
        rec.trace_ms_runs = g.accel->time_traversal(set.rays, any_hit, config.repetitions, out.hits, out.occluded);
        rec.trace_ms = median(rec.trace_ms_runs);
        rec.mrays_per_s = rec.trace_ms > 0.0 ? double(n) / (rec.trace_ms * 1e3) : 0.0;
        rec.build_ms_runs = g.build_runs;
        rec.build_ms = median(g.build_runs);
        rec.stats = g.accel->stats();
        rec.layout_ms = rec.stats.layout_ms;
        rec.device_bytes = rec.stats.device_bytes;
        rec.device_build = g.median_build;
        rec.kernel_resources = g.kernel_resources;
        ReferenceAgreement agreement;
        agreement.reference = reference_label;
        if (any_hit) agreement_any_hit(out.occluded, expected.occluded, agreement.agreement);
        else compare_hits(out.hits, expected.hits, agreement.agreement, agreement.max_rel_t_diff);
        rec.reference = agreement;
        if (config.count_traversal) count_work(*g.accel, set, rec);
        records.push_back(std::move(rec));
    }
}

// Everything built for one scene: our candidates (the first is the
// reference), the peer's qualities and the GPU rows' structures.
struct SceneBuilds {
    std::vector<BuiltCandidate> candidates;
    std::vector<BuiltPeer> peers;
    std::vector<BuiltGpu> gpus;
};

// Builds ours; the last build of each is traced. Without CPU rows only the
// first candidate is built, once: the GPU rows' reference.
std::vector<BuiltCandidate> build_candidates(const SceneGeometry& geometry, const BenchConfig& config,
                                             const std::function<void(const std::string&)>& say) {
    std::vector<BuiltCandidate> built;
    for (const Candidate& candidate : config.candidates) {
        if (!config.cpu && !built.empty()) break;
        say("  building " + candidate.label() +
            (config.cpu ? " x" + std::to_string(config.build_repetitions) : " (CPU reference)"));
        BuiltCandidate b{candidate, nullptr, {}};
        const int builds = config.cpu ? config.build_repetitions : 1;
        for (int r = 0; r < builds; ++r) {
            b.accel.reset();
            const auto start = Clock::now();
            b.accel = build_accel(geometry, candidate.options);
            b.build_runs.push_back(ms_since(start));
        }
        built.push_back(std::move(b));
    }
    return built;
}

std::vector<BuiltPeer> build_peers(const SceneGeometry& geometry, const BenchConfig& config,
                                   const std::function<void(const std::string&)>& say) {
    std::vector<BuiltPeer> peers;
    for (EmbreeQuality quality : config.cpu ? config.embree : std::vector<EmbreeQuality>{}) {
        say(std::string("  building embree/") + embree_quality_name(quality) + " x" +
            std::to_string(config.build_repetitions));
        BuiltPeer p{quality, nullptr, {}};
        for (int r = 0; r < config.build_repetitions; ++r) {
            p.peer.reset();
            p.peer = std::make_unique<EmbreePeer>(geometry, quality, config.threads);
            p.build_runs.push_back(p.peer->build_ms());
        }
        peers.push_back(std::move(p));
    }
    return peers;
}

// The registers, local memory and occupancy of a kernel's trace launches;
// none (and a progress line saying why) when the backend cannot tell.
std::vector<GpuKernelResources> kernel_resources_of(GpuKernel kernel, const Device& device,
                                                    const std::function<void(const std::string&)>& say) {
    try {
        return gpu_kernel_resources(kernel, device);
    } catch (const Error& e) {
        say("  no kernel resources for " + to_string(kernel) + ": " + e.what());
        return {};
    }
}

std::vector<BuiltGpu> build_gpus(const SceneGeometry& geometry, const BenchConfig& config,
                                 const std::function<void(const std::string&)>& say) {
    std::vector<BuiltGpu> gpus;
    const Device device{Device::Kind::Cuda, config.gpu_device};
    for (const GpuCandidate& candidate : config.gpu) {
        say("  building " + to_string(device) + " " + candidate.label() + " x" +
            std::to_string(config.build_repetitions));
        BuiltGpu g{candidate, nullptr, {}, {}, {}};
        BuildOptions options = candidate.build.options;
        options.threads = config.threads;
        options.device = device;
        options.gpu_kernel = candidate.kernel;
        std::vector<std::pair<double, DeviceBuildSummary>> stage_runs;
        for (int r = 0; r < config.build_repetitions; ++r) {
            g.accel.reset();  // frees the device memory of the previous build first
            g.accel = build_accel(geometry, options);
            const AccelStats stats = g.accel->stats();
            g.build_runs.push_back(stats.build_ms);
            stage_runs.emplace_back(stats.build_ms,
                                    DeviceBuildSummary{g.accel->build_report(), stats.node_count, stats.sah_cost});
        }
        if (!stage_runs.empty()) {
            std::sort(stage_runs.begin(), stage_runs.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
            g.median_build = stage_runs[stage_runs.size() / 2].second;
        }
        g.kernel_resources = kernel_resources_of(candidate.kernel, device, say);
        gpus.push_back(std::move(g));
    }
    return gpus;
}

// The figures of one Embree quality on `set`; its answers go to `out`.
PeerFigures trace_peer(const BuiltPeer& built, const RaySet& set, int repetitions, TraceResult& out) {
    const EmbreePeer& peer = *built.peer;
    const size_t n = set.rays.size();
    std::vector<double> runs;
    if (is_any_hit(set.kind)) {
        out.occluded.assign(n, 0);
        runs = timed_runs(repetitions, [&] { peer.occluded(set.rays, out.occluded); });
    } else {
        out.hits.assign(n, Hit{});
        runs = timed_runs(repetitions, [&] { peer.intersect(set.rays, out.hits); });
    }
    PeerFigures f;
    f.quality = built.quality;
    f.trace_ms = median(runs);
    f.mrays_per_s = f.trace_ms > 0.0 ? double(n) / (f.trace_ms * 1e3) : 0.0;
    f.build_ms = median(built.build_runs);
    f.bytes = peer.bytes();
    return f;
}

// The CPU rows of one ray set: the peer first (its answers are the
// reference of the agreement figures), then every candidate.
void trace_cpu_rows(const RaySet& set, const SceneBuilds& builds, const BenchConfig& config,
                    const BenchRecord& prototype, std::vector<BenchRecord>& records) {
    const bool any_hit = is_any_hit(set.kind);
    const size_t n = set.rays.size();
    std::vector<TraceResult> peer_results(builds.peers.size());
    std::vector<PeerFigures> peer_figures;
    for (size_t p = 0; p < builds.peers.size(); ++p)
        peer_figures.push_back(trace_peer(builds.peers[p], set, config.repetitions, peer_results[p]));
    for (const BuiltCandidate& b : builds.candidates) {
        BenchRecord rec = prototype;
        rec.candidate = b.candidate;
        TraceResult out;
        if (any_hit) {
            out.occluded.assign(n, 0);
            rec.trace_ms_runs = timed_runs(config.repetitions, [&] { b.accel->occluded(set.rays, out.occluded); });
        } else {
            out.hits.assign(n, Hit{});
            rec.trace_ms_runs = timed_runs(config.repetitions, [&] { b.accel->intersect(set.rays, out.hits); });
        }
        rec.trace_ms = median(rec.trace_ms_runs);
        rec.mrays_per_s = rec.trace_ms > 0.0 ? double(n) / (rec.trace_ms * 1e3) : 0.0;
        rec.build_ms_runs = b.build_runs;
        rec.build_ms = median(b.build_runs);
        rec.stats = b.accel->stats();
        rec.layout_ms = rec.stats.layout_ms;
        if (config.count_traversal) count_work(*b.accel, set, rec);
        rec.embree = peer_figures;
        for (size_t p = 0; p < builds.peers.size(); ++p) {
            PeerFigures& f = rec.embree[p];
            if (any_hit) {
                agreement_any_hit(out.occluded, peer_results[p].occluded, f.agreement);
                f.max_rel_t_diff = 0.0;
            } else {
                compare_hits(out.hits, peer_results[p].hits, f.agreement, f.max_rel_t_diff);
            }
        }
        records.push_back(std::move(rec));
    }
}

}  // namespace

std::vector<RaySetKind> with_morton_primaries(const std::vector<RaySetKind>& kinds) {
    std::vector<RaySetKind> out;
    const bool named = std::find(kinds.begin(), kinds.end(), RaySetKind::PrimaryMorton) != kinds.end();
    for (RaySetKind kind : kinds) {
        out.push_back(kind);
        if (kind == RaySetKind::Primary && !named) out.push_back(RaySetKind::PrimaryMorton);
    }
    return out;
}

double median(std::vector<double> values) {
    if (values.empty()) return 0.0;
    std::sort(values.begin(), values.end());
    const size_t n = values.size();
    return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

void compare_hits(const std::vector<Hit>& ours, const std::vector<Hit>& peer, double& agreement,
                  double& max_rel_t_diff) {
    size_t same = 0;
    double worst = 0.0;
    for (size_t i = 0; i < ours.size(); ++i) {
        const Hit& a = ours[i];
        const Hit& b = peer[i];
        if (a.found() != b.found()) continue;
        if (!a.found()) {
            ++same;
            continue;
        }
        if (a.prim != b.prim) continue;
        ++same;
        const double scale = std::max(std::fabs(double(a.t)), std::fabs(double(b.t)));
        if (scale > 0.0) worst = std::max(worst, std::fabs(double(a.t) - double(b.t)) / scale);
    }
    agreement = ours.empty() ? 1.0 : double(same) / double(ours.size());
    max_rel_t_diff = worst;
}

namespace {

// Every view and resolution of one scene, every ray set: CPU rows, then GPU rows.
void trace_scene(const LoadedScene& scene, SceneBuilds& builds, const BenchConfig& config,
                 const std::function<void(const std::string&)>& say, std::vector<BenchRecord>& records) {
    const SceneGeometry& geometry = scene.geometry;
    // The reference for the GPU rows' agreement (and for the secondary ray
    // sets) is the first candidate: every correct structure finds the same closest hits.
    const Accel& reference = *builds.candidates.front().accel;
    const std::string reference_label = builds.candidates.front().candidate.label();
    const std::string gpu_device = to_string(Device{Device::Kind::Cuda, config.gpu_device});
    const std::string gpu_name = builds.gpus.empty() ? std::string() : gpu_device_name(config.gpu_device);
    std::vector<int> views = config.views;
    if (views.empty())
        for (int v = 0; v < view_count(scene); ++v) views.push_back(v);
    for (int view_index : views) {
        for (const Resolution& res : config.resolutions) {
            const auto new_record = [&](const RaySet& set, int spp) {
                BenchRecord rec;
                rec.scene = scene.spec.name;
                rec.triangles = geometry.triangles.size();
                rec.load_ms = scene.load_ms;
                rec.view = view_index;
                rec.width = res.width;
                rec.height = res.height;
                rec.ray_set = set.kind;
                rec.rays = set.rays.size();
                rec.samples_per_pixel = spp;
                rec.triangle_bytes = geometry.triangles.size() * sizeof(Triangle);
                return rec;
            };
            const auto describe = [&](const RaySet& set, int spp, const std::string& where) {
                return "  tracing " + std::string(ray_set_name(set.kind)) + " on " + where + ": " +
                       std::to_string(set.rays.size()) + " rays (" + std::to_string(res.width) + "x" +
                       std::to_string(res.height) + ", " + std::to_string(spp) + " spp, view " +
                       std::to_string(view_index) + ")";
            };
            ViewSetup view = make_view_setup(scene, view_index, res.width, res.height);
            // The GPU rows also trace the Morton-ordered primaries beside the scanline ones.
            const std::vector<RaySetKind> gpu_kinds =
                builds.gpus.empty() ? std::vector<RaySetKind>{} : with_morton_primaries(config.ray_sets);
            std::vector<RaySet> cpu_sets, gpu_sets;
            if (config.cpu) {
                view.samples_per_pixel = config.cpu_samples_per_pixel;
                cpu_sets = make_ray_sets(geometry, reference, view, config.ray_sets);
            }
            const bool shared_sets = config.cpu && config.cpu_samples_per_pixel == config.gpu_samples_per_pixel &&
                                     gpu_kinds == config.ray_sets;
            if (!builds.gpus.empty() && !shared_sets) {
                view.samples_per_pixel = config.gpu_samples_per_pixel;
                gpu_sets = make_ray_sets(geometry, reference, view, gpu_kinds);
            }
            const std::vector<RaySet>& device_sets = shared_sets ? cpu_sets : gpu_sets;
            const std::vector<RaySetKind>& kinds = builds.gpus.empty() ? config.ray_sets : gpu_kinds;
            for (RaySetKind kind : kinds) {
                if (config.cpu) {
                    const auto cpu_set = std::find_if(cpu_sets.begin(), cpu_sets.end(),
                                                      [&](const RaySet& s) { return s.kind == kind; });
                    if (cpu_set != cpu_sets.end()) {
                        say(describe(*cpu_set, config.cpu_samples_per_pixel, "cpu"));
                        trace_cpu_rows(*cpu_set, builds, config, new_record(*cpu_set, config.cpu_samples_per_pixel),
                                       records);
                    }
                }
                if (builds.gpus.empty()) continue;
                const RaySet& set = *std::find_if(device_sets.begin(), device_sets.end(),
                                                  [&](const RaySet& s) { return s.kind == kind; });
                say(describe(set, config.gpu_samples_per_pixel, gpu_device));
                BenchRecord prototype = new_record(set, config.gpu_samples_per_pixel);
                prototype.device = gpu_device;
                prototype.gpu = gpu_name;
                trace_gpu_rows(set, reference, reference_label, builds.gpus, config, prototype, records);
            }
        }
    }
}

void check_config(const BenchConfig& config) {
    if (config.repetitions < 1 || config.build_repetitions < 1)
        throw Error("bench: repetitions must be at least 1");
    if (config.candidates.empty()) throw Error("bench: no implemented structure selected");
    if (!config.cpu && config.gpu.empty()) throw Error("bench: neither CPU nor GPU rows selected");
    if (config.cpu_samples_per_pixel < 1 || config.gpu_samples_per_pixel < 1)
        throw Error("bench: samples per pixel must be at least 1");
    if (!config.gpu.empty()) require_device(Device{Device::Kind::Cuda, config.gpu_device});
}

}  // namespace

std::string gpu_device_name(int device) {
    for (const DeviceInfo& info : list_cuda_devices().devices)
        if (info.index == device) return info.name;
    return "";
}

std::vector<BenchRecord> run_bench(const BenchConfig& config, std::ostream& log,
                                   const std::function<void(const std::vector<BenchRecord>&)>& on_scene) {
    check_config(config);
    std::vector<BenchRecord> all_records;
    const std::function<void(const std::string&)> say = [&](const std::string& line) {
        if (config.progress) log << line << std::endl;
    };
    parallel::with_threads(config.threads, [&] {
        for (const std::string& scene_name : config.scenes) {
            LoadedScene scene;
            try {
                scene = load_bench_scene(resolve_scene(scene_name, config.scenes_dir));
            } catch (const Error& e) {
                if (!config.skip_unloadable) throw;
                log << "skipped scene " << scene_name << ": " << e.what() << std::endl;
                continue;
            }
            say(scene.spec.name + ": " + std::to_string(scene.geometry.triangles.size()) + " triangles, loaded in " +
                std::to_string(int(scene.load_ms)) + " ms");
            SceneBuilds builds{build_candidates(scene.geometry, config, say), build_peers(scene.geometry, config, say),
                               build_gpus(scene.geometry, config, say)};
            std::vector<BenchRecord> scene_records;
            trace_scene(scene, builds, config, say, scene_records);
            if (on_scene) on_scene(scene_records);
            all_records.insert(all_records.end(), scene_records.begin(), scene_records.end());
        }
    });
    return all_records;
}

}  // namespace rf::bench
