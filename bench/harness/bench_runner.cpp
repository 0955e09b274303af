#include "bench_runner.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <ostream>

#include "backend/cpu/parallel.h"
#include "gpu_bench.h"
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
    std::unique_ptr<GpuTracer> tracer;
    std::vector<double> build_runs;  // GpuTracer::stats().build_ms of each build
    GpuBuildStages median_build;     // the stages of the build with the median build_ms
};

// The GPU rows of one ray set: rays resident on the device, the kernel time
// of one launch per run, hits compared with the CPU reference's.
void trace_gpu_rows(const RaySet& set, const Accel& reference, const std::string& reference_label,
                    std::vector<BuiltGpu>& gpus, const BenchConfig& config, const BenchRecord& prototype,
                    std::vector<BenchRecord>& records) {
    const bool any_hit = is_any_hit(set.kind);
    const size_t n = set.rays.size();
    TraceResult expected;
    if (any_hit) {
        expected.occluded.assign(n, 0);
        reference.occluded(set.rays, expected.occluded);
    } else {
        expected.hits.assign(n, Hit{});
        reference.intersect(set.rays, expected.hits);
    }
    for (BuiltGpu& g : gpus) {
        BenchRecord rec = prototype;
        rec.candidate = g.candidate.build;
        GpuTracer& tracer = *g.tracer;
        tracer.upload(set.rays);
        tracer.trace(any_hit);  // warm-up
        for (int r = 0; r < config.repetitions; ++r) rec.trace_ms_runs.push_back(tracer.trace(any_hit));
        rec.trace_ms = median(rec.trace_ms_runs);
        rec.mrays_per_s = rec.trace_ms > 0.0 ? double(n) / (rec.trace_ms * 1e3) : 0.0;
        rec.build_ms_runs = g.build_runs;
        rec.build_ms = median(g.build_runs);
        rec.stats = tracer.stats();
        rec.layout_ms = rec.stats.layout_ms;
        rec.device_bytes = tracer.device_bytes();
        rec.device_build = g.median_build;
        ReferenceAgreement agreement;
        agreement.reference = reference_label;
        TraceResult out;  // what the last timed launch found
        if (any_hit) {
            out.occluded.assign(n, 0);
            tracer.download_occluded(out.occluded);
            agreement_any_hit(out.occluded, expected.occluded, agreement.agreement);
        } else {
            out.hits.assign(n, Hit{});
            tracer.download_hits(out.hits);
            compare_hits(out.hits, expected.hits, agreement.agreement, agreement.max_rel_t_diff);
        }
        rec.reference = agreement;
        if (config.count_traversal) {
            TraversalTotals totals;
            tracer.count_traversal(set.rays, any_hit, totals);
            if (totals.rays > 0) {
                rec.has_counts = true;
                rec.steps_per_ray = double(totals.steps) / double(totals.rays);
                rec.prims_per_ray = double(totals.prim_tests) / double(totals.rays);
                rec.restarts_per_ray = double(totals.restarts) / double(totals.rays);
            }
        }
        records.push_back(std::move(rec));
    }
}

}  // namespace

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

std::vector<BenchRecord> run_bench(const BenchConfig& config, std::ostream& log,
                                   const std::function<void(const std::vector<BenchRecord>&)>& on_scene) {
    if (config.repetitions < 1 || config.build_repetitions < 1)
        throw Error("bench: repetitions must be at least 1");
    if (config.candidates.empty()) throw Error("bench: no implemented structure selected");
    if (!config.cpu && config.gpu.empty()) throw Error("bench: neither CPU nor GPU rows selected");
    if (config.cpu_samples_per_pixel < 1 || config.gpu_samples_per_pixel < 1)
        throw Error("bench: samples per pixel must be at least 1");
    std::string gpu_name;
    if (!config.gpu.empty()) {
        require_gpu_device(config.gpu_device);
        gpu_name = gpu_device_name(config.gpu_device);
    }
    const std::string gpu_device = "cuda:" + std::to_string(config.gpu_device);
    std::vector<BenchRecord> all_records;
    const auto say = [&](const std::string& line) {
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
            const SceneGeometry& geometry = scene.geometry;
            say(scene.spec.name + ": " + std::to_string(geometry.triangles.size()) + " triangles, loaded in " +
                std::to_string(int(scene.load_ms)) + " ms");

            // Builds: ours, then the peer's qualities; the last build of each is traced.
            std::vector<BuiltCandidate> built;
            for (const Candidate& candidate : config.candidates) {
                if (!config.cpu && !built.empty()) break;  // GPU rows only: just the reference
                say("  building " + candidate.label() + (config.cpu ? " x" + std::to_string(config.build_repetitions)
                                                                    : " (CPU reference)"));
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
            // The reference for primary hits (and for the GPU rows' agreement)
            // is the first candidate: every correct structure finds the same closest hits.
            const Accel& reference = *built.front().accel;
            const std::string reference_label = built.front().candidate.label();
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
            std::vector<BuiltGpu> gpus;
            for (const GpuCandidate& candidate : config.gpu) {
                say("  building " + gpu_device + " " + candidate.label() + " x" +
                    std::to_string(config.build_repetitions));
                BuiltGpu g{candidate, nullptr, {}, {}};
                BuildOptions options = candidate.build.options;
                options.threads = config.threads;
                std::vector<std::pair<double, GpuBuildStages>> stage_runs;
                for (int r = 0; r < config.build_repetitions; ++r) {
                    g.tracer.reset();  // frees the device memory of the previous build first
                    g.tracer = std::make_unique<GpuTracer>(geometry, candidate.kernel, options, config.gpu_device);
                    g.build_runs.push_back(g.tracer->stats().build_ms);
                    stage_runs.emplace_back(g.build_runs.back(), g.tracer->build_stages());
                }
                if (!stage_runs.empty()) {
                    std::sort(stage_runs.begin(), stage_runs.end(),
                              [](const auto& a, const auto& b) { return a.first < b.first; });
                    g.median_build = stage_runs[stage_runs.size() / 2].second;
                }
                gpus.push_back(std::move(g));
            }

            std::vector<int> views = config.views;
            if (views.empty())
                for (int v = 0; v < view_count(scene); ++v) views.push_back(v);
            std::vector<BenchRecord> scene_records;
            const auto new_record = [&](int view_index, const Resolution& res, RaySetKind kind, size_t n, int spp) {
                BenchRecord rec;
                rec.scene = scene.spec.name;
                rec.triangles = geometry.triangles.size();
                rec.load_ms = scene.load_ms;
                rec.view = view_index;
                rec.width = res.width;
                rec.height = res.height;
                rec.ray_set = kind;
                rec.rays = n;
                rec.samples_per_pixel = spp;
                rec.triangle_bytes = geometry.triangles.size() * sizeof(Triangle);
                return rec;
            };
            for (int view_index : views) {
                for (const Resolution& res : config.resolutions) {
                    ViewSetup view = make_view_setup(scene, view_index, res.width, res.height);
                    std::vector<RaySet> cpu_sets, gpu_sets;
                    if (config.cpu) {
                        view.samples_per_pixel = config.cpu_samples_per_pixel;
                        cpu_sets = make_ray_sets(geometry, reference, view, config.ray_sets);
                    }
                    const bool shared_sets = config.cpu && config.cpu_samples_per_pixel == config.gpu_samples_per_pixel;
                    if (!gpus.empty() && !shared_sets) {
                        view.samples_per_pixel = config.gpu_samples_per_pixel;
                        gpu_sets = make_ray_sets(geometry, reference, view, config.ray_sets);
                    }
                    const std::vector<RaySet>& device_sets = shared_sets ? cpu_sets : gpu_sets;
                    const auto describe = [&](const RaySet& set, int spp, const std::string& where) {
                        return "  tracing " + std::string(ray_set_name(set.kind)) + " on " + where + ": " +
                               std::to_string(set.rays.size()) + " rays (" + std::to_string(res.width) + "x" +
                               std::to_string(res.height) + ", " + std::to_string(spp) + " spp, view " +
                               std::to_string(view_index) + ")";
                    };
                    for (size_t k = 0; k < config.ray_sets.size(); ++k) {
                        if (config.cpu) {
                            const RaySet& set = cpu_sets[k];
                            const bool any_hit = is_any_hit(set.kind);
                            const size_t n = set.rays.size();
                            say(describe(set, config.cpu_samples_per_pixel, "cpu"));
                            // The peer first: its results are the reference for agreement.
                            std::vector<TraceResult> peer_results(peers.size());
                            std::vector<PeerFigures> peer_figures;
                            for (size_t p = 0; p < peers.size(); ++p) {
                                TraceResult& out = peer_results[p];
                                const EmbreePeer& peer = *peers[p].peer;
                                std::vector<double> runs;
                                if (any_hit) {
                                    out.occluded.assign(n, 0);
                                    runs = timed_runs(config.repetitions, [&] { peer.occluded(set.rays, out.occluded); });
                                } else {
                                    out.hits.assign(n, Hit{});
                                    runs = timed_runs(config.repetitions, [&] { peer.intersect(set.rays, out.hits); });
                                }
                                PeerFigures f;
                                f.quality = peers[p].quality;
                                f.trace_ms = median(runs);
                                f.mrays_per_s = f.trace_ms > 0.0 ? double(n) / (f.trace_ms * 1e3) : 0.0;
                                f.build_ms = median(peers[p].build_runs);
                                f.bytes = peer.bytes();
                                peer_figures.push_back(f);
                            }
                            for (const BuiltCandidate& b : built) {
                                BenchRecord rec = new_record(view_index, res, set.kind, n, config.cpu_samples_per_pixel);
                                rec.candidate = b.candidate;
                                TraceResult out;
                                if (any_hit) {
                                    out.occluded.assign(n, 0);
                                    rec.trace_ms_runs =
                                        timed_runs(config.repetitions, [&] { b.accel->occluded(set.rays, out.occluded); });
                                } else {
                                    out.hits.assign(n, Hit{});
                                    rec.trace_ms_runs =
                                        timed_runs(config.repetitions, [&] { b.accel->intersect(set.rays, out.hits); });
                                }
                                rec.trace_ms = median(rec.trace_ms_runs);
                                rec.mrays_per_s = rec.trace_ms > 0.0 ? double(n) / (rec.trace_ms * 1e3) : 0.0;
                                rec.build_ms_runs = b.build_runs;
                                rec.build_ms = median(b.build_runs);
                                rec.stats = b.accel->stats();
                                rec.layout_ms = rec.stats.layout_ms;
                                if (config.count_traversal) {
                                    TraversalTotals totals;
                                    if (b.accel->count_traversal(set.rays, any_hit, totals) && totals.rays > 0) {
                                        rec.has_counts = true;
                                        rec.steps_per_ray = double(totals.steps) / double(totals.rays);
                                        rec.prims_per_ray = double(totals.prim_tests) / double(totals.rays);
                                        rec.restarts_per_ray = double(totals.restarts) / double(totals.rays);
                                    }
                                }
                                rec.embree = peer_figures;
                                for (size_t p = 0; p < peers.size(); ++p) {
                                    PeerFigures& f = rec.embree[p];
                                    if (any_hit) {
                                        agreement_any_hit(out.occluded, peer_results[p].occluded, f.agreement);
                                        f.max_rel_t_diff = 0.0;
                                    } else {
                                        compare_hits(out.hits, peer_results[p].hits, f.agreement, f.max_rel_t_diff);
                                    }
                                }
                                scene_records.push_back(std::move(rec));
                            }
                        }
                        if (gpus.empty()) continue;

                        const RaySet& set = device_sets[k];
                        say(describe(set, config.gpu_samples_per_pixel, gpu_device));
                        BenchRecord prototype =
                            new_record(view_index, res, set.kind, set.rays.size(), config.gpu_samples_per_pixel);
                        prototype.device = gpu_device;
                        prototype.gpu = gpu_name;
                        trace_gpu_rows(set, reference, reference_label, gpus, config, prototype, scene_records);
                    }
                }
            }
            if (on_scene) on_scene(scene_records);
            all_records.insert(all_records.end(), scene_records.begin(), scene_records.end());
        }
    });
    return all_records;
}

}  // namespace rf::bench
