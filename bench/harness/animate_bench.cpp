// `rayforge bench --animate` and `--cluster-table` (docs/animation.md).
//
// Papers: Garanzha 2014 ch. 2 (BVH update from the previous frame's BVH;
// the per-frame figures of Figs. 2.7-2.10: update time against a full
// rebuild, trace speed of the updated tree against the rebuilt one, counts of
// refits, rebuilt subtrees and migrations) and ch. 3 (Table 3.1: BVHs over
// clusters of connected triangles, Acc(k) against Naive(k)).
// Data: each update method is a World over its own copy of the scene,
// moved frame by frame with World::set_time (the scene evaluated, its
// triangles and structure updated, as render --frames and the viewer move
// theirs); the bench's own copy is evaluated the same way (Scene::set_time,
// SceneGeometry::update) for the reference rebuild and the Embree dynamic
// peer (over its copy of those triangles). Each frame's ray sets come from
// the rebuild of that frame and are traced unchanged by every structure.
// Parallelism: builds, updates and traces run inside one TBB arena of
// `threads` threads; Embree gets its own device of as many threads.
// Determinism: the rays are a function of the frame's geometry and camera;
// the times are wall-clock.
#include "animate_bench.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <memory>
#include <ostream>

#include <nlohmann/json.hpp>

#include "accel/bvh/builders/cluster_generation.h"
#include "core/parallel.h"
#include "bench_report.h"
#include "bench_runner.h"
#include "rayforge/core/error.h"
#include "rayforge/world.h"

namespace rf::bench {
namespace {

using Clock = std::chrono::steady_clock;
using Json = nlohmann::json;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

int parse_int(const std::string& text, const std::string& what) {
    try {
        size_t used = 0;
        const int value = std::stoi(text, &used);
        if (used == text.size()) return value;
    } catch (const std::exception&) {
    }
    throw Error(what);
}

// What one structure answered for every ray of every set.
struct SetAnswers {
    std::vector<std::vector<Hit>> hits;        // closest-hit sets
    std::vector<std::vector<uint8_t>> occluded;  // any-hit sets
};

// Traces every set `repetitions` times (median ms) through `intersect` /
// `occluded`; compares with `reference` when given, or keeps the answers in
// `keep` (the reference itself).
template <class Tracer>
FrameTraces trace_sets(const Tracer& tracer, const std::vector<RaySet>& sets, int repetitions,
                       const SetAnswers* reference, SetAnswers* keep) {
    FrameTraces out;
    SetAnswers answers;
    answers.hits.resize(sets.size());
    answers.occluded.resize(sets.size());
    for (size_t s = 0; s < sets.size(); ++s) {
        const RaySet& set = sets[s];
        const bool any_hit = is_any_hit(set.kind);
        std::vector<double> runs;
        for (int r = 0; r < std::max(1, repetitions); ++r) {
            const auto start = Clock::now();
            if (any_hit) {
                answers.occluded[s].assign(set.rays.size(), 0);
                tracer.occluded(set.rays, answers.occluded[s]);
            } else {
                answers.hits[s].assign(set.rays.size(), Hit{});
                tracer.intersect(set.rays, answers.hits[s]);
            }
            runs.push_back(ms_since(start));
        }
        out.trace_ms.push_back(median(runs));
        if (!reference) continue;
        double agreement = 1.0, max_dt = 0.0;
        if (any_hit) {
            size_t same = 0;
            for (size_t i = 0; i < set.rays.size(); ++i)
                same += (answers.occluded[s][i] != 0) == (reference->occluded[s][i] != 0) ? 1 : 0;
            agreement = set.rays.empty() ? 1.0 : double(same) / double(set.rays.size());
        } else {
            compare_hits(answers.hits[s], reference->hits[s], agreement, max_dt);
        }
        out.agreement = std::min(out.agreement, agreement);
    }
    if (keep) *keep = std::move(answers);
    return out;
}

// The frame's time evaluated in place; returns what moved.
GeometryChange go_to_frame(LoadedScene& scene, int frame) {
    const GeometryChange change = scene.scene.set_time(scene.scene.animation.frame_time(frame));
    scene.geometry.update(scene.scene, change);
    return change;
}

// Every mesh and instance: a still scene's "frame" for the cluster builds.
GeometryChange everything(const Scene& scene) {
    GeometryChange change;
    for (uint32_t m = 0; m < uint32_t(scene.meshes.size()); ++m) change.meshes.push_back(m);
    for (uint32_t i = 0; i < uint32_t(scene.instances.size()); ++i) change.instances.push_back(i);
    return change;
}

// The protocol's sets at the view, and the diffuse set at `diffuse_view`
// (sized so that it holds about `diffuse_rays`), cut to that count.
std::vector<RaySet> frame_ray_sets(const SceneGeometry& geometry, const Accel& reference, const ViewSetup& view,
                                   const ViewSetup& diffuse_view, const std::vector<RaySetKind>& kinds,
                                   size_t diffuse_rays) {
    std::vector<RaySetKind> at_view;
    for (RaySetKind kind : kinds)
        if (kind != RaySetKind::Diffuse || diffuse_rays == 0) at_view.push_back(kind);
    std::vector<RaySet> made = make_ray_sets(geometry, reference, view, at_view);
    std::vector<RaySet> sets;
    for (RaySetKind kind : kinds) {
        if (kind == RaySetKind::Diffuse && diffuse_rays > 0) {
            RaySet diffuse = std::move(make_ray_sets(geometry, reference, diffuse_view, {kind}).front());
            if (diffuse.rays.size() > diffuse_rays) diffuse.rays.resize(diffuse_rays);
            sets.push_back(std::move(diffuse));
            continue;
        }
        for (RaySet& set : made)
            if (set.kind == kind) sets.push_back(set);
    }
    return sets;
}

// A view with enough pixels for `diffuse_rays` diffuse rays (8 per primary
// hit), judged from the hits of `view`'s primary rays, with 10% to spare.
ViewSetup diffuse_view_for(const Accel& reference, const ViewSetup& view, size_t diffuse_rays) {
    ViewSetup out = view;
    if (diffuse_rays == 0) return out;
    const RaySet primary = make_primary_rays(view);
    std::vector<Hit> hits(primary.rays.size());
    reference.intersect(primary.rays, hits);
    size_t hit_count = 0;
    for (const Hit& h : hits) hit_count += h.found() ? 1 : 0;
    if (hit_count == 0) return out;
    const double scale = std::sqrt(1.1 * double(diffuse_rays) / double(hit_count * size_t(kAoSamplesPerHit)));
    out.width = std::clamp(int(std::ceil(view.width * scale)), 1, 16384);
    out.height = std::clamp(int(std::ceil(view.height * scale)), 1, 16384);
    return out;
}

std::string first_line(const std::exception& e) {
    std::string text = e.what();
    const size_t nl = text.find('\n');
    return nl == std::string::npos ? text : text.substr(0, nl);
}

// --- the animation ---

struct Built {
    std::vector<std::unique_ptr<World>> worlds;           // one per method; null where it failed
    std::vector<std::unique_ptr<EmbreeDynamicPeer>> peers;
};

Built build_structures(LoadedScene& scene, const AnimateConfig& config, AnimateResult& result,
                       const std::function<void(const std::string&)>& say) {
    Built built;
    for (UpdateMethod method : config.methods) {
        MethodColumn column;
        column.method = method;
        WorldOptions options;
        options.device = config.device;
        options.build = config.build;
        options.update = config.update;
        options.update.method = method;
        say("  building " + to_string(method));
        try {
            built.worlds.push_back(make_world(scene.scene, options));  // the scene at the build frame
            column.initial_build_ms = built.worlds.back()->commit().commit_ms;
            column.ok = true;
        } catch (const std::exception& e) {
            built.worlds.push_back(nullptr);
            column.error = first_line(e);
        }
        result.methods.push_back(column);
    }
    for (EmbreeUpdate update : config.embree) {
        PeerColumn column;
        column.update = update;
        say(std::string("  building embree ") + embree_update_name(update));
        try {
            built.peers.push_back(std::make_unique<EmbreeDynamicPeer>(scene.geometry, update, config.threads));
            column.build_ms = built.peers.back()->build_ms();
            column.ok = true;
        } catch (const std::exception& e) {
            built.peers.push_back(nullptr);
            column.error = first_line(e);
        }
        result.embree.push_back(column);
    }
    return built;
}

// Every method's world moved to the frame and traced; one that throws is
// dropped for the rest. The update time is the structure's own (the
// scene's evaluation is the same for every method: AnimateFrame::scene_ms).
void update_methods(Built& built, const std::vector<RaySet>& sets, const SetAnswers& reference,
                    const AnimateConfig& config, AnimateFrame& frame) {
    for (std::unique_ptr<World>& world : built.worlds) {
        MethodFrame m;
        if (!world) {
            m.error = "not built";
            frame.methods.push_back(m);
            continue;
        }
        try {
            m.stats = world->set_time(frame.time);
            m.update_ms = m.stats.update_ms;
            // A frame where nothing moved leaves the tree (and reports no cost).
            if (!(m.stats.sah_cost > 0.0)) m.stats.sah_cost = world->accel().stats().sah_cost;
            m.traces = trace_sets(*world, sets, config.repetitions, &reference, nullptr);
            m.ok = true;
        } catch (const std::exception& e) {
            m.error = "failed at frame " + std::to_string(frame.frame) + ": " + first_line(e);
            world.reset();
        }
        frame.methods.push_back(m);
    }
}

void update_peers(Built& built, const SceneGeometry& geometry, const std::vector<RaySet>& sets,
                  const SetAnswers& reference, const AnimateConfig& config, AnimateFrame& frame) {
    for (std::unique_ptr<EmbreeDynamicPeer>& peer : built.peers) {
        PeerFrame p;
        if (!peer) {
            p.error = "not built";
            frame.embree.push_back(p);
            continue;
        }
        try {
            p.update_ms = peer->update(geometry);
            p.copy_ms = peer->copy_ms();
            p.traces = trace_sets(*peer, sets, config.repetitions, &reference, nullptr);
            p.ok = true;
        } catch (const std::exception& e) {
            p.error = "failed at frame " + std::to_string(frame.frame) + ": " + first_line(e);
            peer.reset();
        }
        frame.embree.push_back(p);
    }
}

AnimateFrame run_frame(LoadedScene& scene, int index, Built& built, ViewSetup& view, ViewSetup& diffuse_view,
                       const AnimateConfig& config) {
    AnimateFrame frame;
    frame.frame = index;
    frame.time = scene.scene.animation.frame_time(index);
    auto start = Clock::now();
    const GeometryChange change = go_to_frame(scene, index);
    frame.scene_ms = ms_since(start);
    if (change.camera && scene.spec.views.empty()) {
        view.camera = scene.scene.camera_or_default();
        diffuse_view.camera = view.camera;
    }
    start = Clock::now();
    const std::unique_ptr<Accel> rebuilt = build_accel(scene.geometry, config.build);
    frame.rebuild_ms = ms_since(start);
    frame.rebuild_sah = rebuilt->stats().sah_cost;
    const std::vector<RaySet> sets =
        frame_ray_sets(scene.geometry, *rebuilt, view, diffuse_view, config.ray_sets, config.diffuse_rays);
    for (const RaySet& set : sets) frame.rays.push_back(set.rays.size());
    SetAnswers reference;
    frame.rebuild_trace_ms = trace_sets(*rebuilt, sets, config.repetitions, nullptr, &reference).trace_ms;
    update_methods(built, sets, reference, config, frame);
    update_peers(built, scene.geometry, sets, reference, config, frame);
    return frame;
}

}  // namespace

FrameRange parse_frame_range(const std::string& text) {
    const std::string message = "--frames: expected FIRST:LAST or FIRST:LAST:STEP (frames >= 0, LAST >= FIRST, "
                                "STEP >= 1), got '" + text + "'";
    std::vector<std::string> parts;
    size_t begin = 0;
    while (true) {
        const size_t colon = text.find(':', begin);
        parts.push_back(text.substr(begin, colon - begin));
        if (colon == std::string::npos) break;
        begin = colon + 1;
    }
    if (parts.size() < 2 || parts.size() > 3) throw Error(message);
    FrameRange range;
    range.first = parse_int(parts[0], message);
    range.last = parse_int(parts[1], message);
    if (parts.size() == 3) range.step = parse_int(parts[2], message);
    if (range.first < 0 || range.last < range.first || range.step < 1) throw Error(message);
    return range;
}

std::vector<int> frame_sequence(const FrameRange& range, int frame_count, bool backwards) {
    const int last_frame = std::max(0, frame_count - 1);
    const int last = range.last < 0 ? last_frame : std::min(range.last, last_frame);
    std::vector<int> forward;
    for (int f = std::min(range.first, last); f <= last; f += std::max(1, range.step)) forward.push_back(f);
    if (!backwards || forward.size() < 2) return forward;
    std::vector<int> frames = forward;
    frames.insert(frames.end(), forward.rbegin() + 1, forward.rend());
    frames.insert(frames.end(), forward.begin() + 1, forward.end());
    return frames;
}

AnimateResult run_animate_bench(LoadedScene& scene, const AnimateConfig& config, std::ostream& log) {
    if (!scene.scene.animated())
        throw Error(scene.spec.name + ": the scene has no animation (--animate needs an animated scene)");
    const std::vector<int> frames = frame_sequence(config.frames, scene.scene.animation.frame_count(), config.backwards);
    if (frames.size() < 2)
        throw Error("--frames: the animation of " + scene.spec.name + " has " +
                    std::to_string(scene.scene.animation.frame_count()) +
                    " frames; at least two are needed (one to build at, one to update to)");
    AnimateResult result;
    result.scene = scene.spec.name;
    result.triangles = scene.geometry.size();
    result.frame_count = scene.scene.animation.frame_count();
    result.threads = config.threads > 0 ? config.threads : machine_info().cores;
    result.build = to_string(config.build.builder) + "/" + to_string(config.build.layout);
    result.ray_sets = config.ray_sets;
    result.build_frame = frames.front();
    auto say = [&](const std::string& line) {
        if (config.progress) log << line << '\n' << std::flush;
    };
    BuildOptions build = config.build;
    build.threads = config.threads;
    AnimateConfig run = config;
    run.build = build;
    parallel::with_threads(config.threads, [&] {
        say(scene.spec.name + ": frame " + std::to_string(frames.front()) + ", building");
        go_to_frame(scene, frames.front());
        Built built = build_structures(scene, run, result, say);
        ViewSetup view = make_view_setup(scene, 0, config.width, config.height);
        const std::unique_ptr<Accel> first = build_accel(scene.geometry, build);
        ViewSetup diffuse_view = diffuse_view_for(*first, view, config.diffuse_rays);
        for (size_t i = 1; i < frames.size(); ++i) {
            say(scene.spec.name + ": frame " + std::to_string(frames[i]) + " (" + std::to_string(i) + "/" +
                std::to_string(frames.size() - 1) + ")");
            result.frames.push_back(run_frame(scene, frames[i], built, view, diffuse_view, run));
        }
    });
    return result;
}

// --- reports ---

namespace {

std::string fmt(const char* format, double value) {
    if (!std::isfinite(value)) return "-";
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), format, value);
    return buffer;
}

std::string pad(const std::string& text, size_t width) {
    return text.size() >= width ? text : std::string(width - text.size(), ' ') + text;
}

std::string padl(const std::string& text, size_t width) {
    return text.size() >= width ? text : text + std::string(width - text.size(), ' ');
}

double mrays(size_t rays, double ms) { return ms > 0.0 ? double(rays) / (ms * 1e3) : 0.0; }

// Sums over the frames where a structure answered.
struct Totals {
    int frames = 0;
    double update_ms = 0.0, copy_ms = 0.0, rebuild_ms = 0.0, sah = 0.0, rebuilt_sah = 0.0;
    std::vector<double> trace_ms, rebuilt_trace_ms;
    std::vector<size_t> rays;
    double agreement = 1.0;
    UpdateStats counts;          // summed
    double diffuse_total_ms = 0.0;  // update + diffuse trace
    int diffuse_set = -1;
};

void add_frame(Totals& t, const AnimateFrame& f, double update_ms, const FrameTraces& traces, int diffuse_set) {
    const size_t sets = f.rays.size();
    if (t.trace_ms.empty()) {
        t.trace_ms.assign(sets, 0.0);
        t.rebuilt_trace_ms.assign(sets, 0.0);
        t.rays.assign(sets, 0);
    }
    ++t.frames;
    t.update_ms += update_ms;
    t.rebuild_ms += f.rebuild_ms;
    t.rebuilt_sah += f.rebuild_sah;
    for (size_t s = 0; s < sets; ++s) {
        t.trace_ms[s] += traces.trace_ms[s];
        t.rebuilt_trace_ms[s] += f.rebuild_trace_ms[s];
        t.rays[s] += f.rays[s];
    }
    t.agreement = std::min(t.agreement, traces.agreement);
    t.diffuse_set = diffuse_set;
    if (diffuse_set >= 0) t.diffuse_total_ms += update_ms + traces.trace_ms[size_t(diffuse_set)];
}

int diffuse_index(const AnimateResult& r) {
    for (size_t s = 0; s < r.ray_sets.size(); ++s)
        if (r.ray_sets[s] == RaySetKind::Diffuse) return int(s);
    return -1;
}

// "12.34 (97%)": our rate and its share of the rebuilt tree's.
std::string rate_cell(size_t rays, double ms, double rebuilt_ms) {
    const double ours = mrays(rays, ms), theirs = mrays(rays, rebuilt_ms);
    return fmt("%.2f", ours) + " (" + (theirs > 0.0 ? fmt("%.0f%%", 100.0 * ours / theirs) : "-") + ")";
}

void print_header(std::ostream& out, const AnimateResult& r) {
    out << "\n== " << r.scene << " (" << thousands(r.triangles) << " triangles, " << r.frame_count
        << " frames): --animate, " << r.build << ", " << r.threads << " threads; built at frame " << r.build_frame
        << ", " << r.frames.size() << " frames updated\n";
    if (r.frames.empty()) return;
    out << "rays per frame (frame " << r.frames.front().frame << "):";
    for (size_t s = 0; s < r.ray_sets.size(); ++s)
        out << ' ' << ray_set_name(r.ray_sets[s]) << ' ' << thousands(r.frames.front().rays[s]);
    out << "; Mrays/s (share of the rebuilt tree's rate on the same rays)\n";
}

void print_method_frames(std::ostream& out, const AnimateResult& r, size_t m) {
    const MethodColumn& c = r.methods[m];
    out << "\n-- " << to_string(c.method) << ": ";
    if (!c.ok) {
        out << "n/a (" << c.error << ")\n";
        return;
    }
    out << "initial build " << fmt("%.1f", c.initial_build_ms) << " ms\n";
    const bool adapt = c.method == UpdateMethod::Adapt, two_level = c.method == UpdateMethod::TwoLevel;
    out << pad("frame", 6) << pad("update ms", 11) << pad("rebuild ms", 12) << pad("speed-up", 10) << pad("SAH", 9)
        << pad("rebuilt", 9) << pad("drift", 8);
    for (RaySetKind kind : r.ray_sets) out << pad(ray_set_name(kind), 16);
    out << pad("agree", 8);
    if (adapt) out << pad("refitted", 10) << pad("rebuilt", 9) << pad("(nodes)", 9) << pad("migrated", 10);
    if (two_level) out << pad("meshes", 8);
    out << '\n';
    for (const AnimateFrame& f : r.frames) {
        const MethodFrame& mf = f.methods[m];
        out << pad(std::to_string(f.frame), 6);
        if (!mf.ok) {
            out << "  n/a (" << mf.error << ")\n";
            continue;
        }
        const double drift = f.rebuild_sah > 0.0 ? 100.0 * (mf.stats.sah_cost / f.rebuild_sah - 1.0) : NAN;
        out << pad(fmt("%.2f", mf.update_ms), 11) << pad(fmt("%.2f", f.rebuild_ms), 12)
            << pad(fmt("%.2fx", f.rebuild_ms / mf.update_ms), 10) << pad(fmt("%.1f", mf.stats.sah_cost), 9)
            << pad(fmt("%.1f", f.rebuild_sah), 9) << pad(fmt("%+.1f%%", drift), 8);
        for (size_t s = 0; s < r.ray_sets.size(); ++s)
            out << pad(rate_cell(f.rays[s], mf.traces.trace_ms[s], f.rebuild_trace_ms[s]), 16);
        out << pad(fmt("%.4f", mf.traces.agreement), 8);
        if (adapt)
            out << pad(thousands(mf.stats.refitted_nodes), 10) << pad(thousands(mf.stats.rebuilt_subtrees), 9)
                << pad(thousands(mf.stats.rebuilt_nodes), 9) << pad(thousands(mf.stats.migrations), 10);
        if (two_level) out << pad(thousands(mf.stats.meshes_updated), 8);
        out << '\n';
    }
}

void print_peer_frames(std::ostream& out, const AnimateResult& r) {
    if (r.embree.empty()) return;
    out << "\n-- embree " << embree_version() << " (same vertex positions each frame; ms = rtcCommitGeometry + "
        << "rtcCommitScene, the copy into its buffer apart):";
    for (const PeerColumn& c : r.embree)
        out << ' ' << embree_update_name(c.update)
            << (c.ok ? " built in " + fmt("%.1f", c.build_ms) + " ms" : " n/a (" + c.error + ")") << ';';
    out << '\n' << pad("frame", 6);
    for (const PeerColumn& c : r.embree) {
        out << pad(std::string(embree_update_name(c.update)) + " ms", 11);
        for (RaySetKind kind : r.ray_sets) out << pad(ray_set_name(kind), 16);
    }
    out << '\n';
    for (const AnimateFrame& f : r.frames) {
        out << pad(std::to_string(f.frame), 6);
        for (const PeerFrame& p : f.embree) {
            if (!p.ok) {
                out << pad("n/a", 11 + 16 * r.ray_sets.size());
                continue;
            }
            out << pad(fmt("%.2f", p.update_ms), 11);
            for (size_t s = 0; s < r.ray_sets.size(); ++s)
                out << pad(rate_cell(f.rays[s], p.traces.trace_ms[s], f.rebuild_trace_ms[s]), 16);
        }
        out << '\n';
    }
}

// One summary row: mean update ms, its speed-up over the rebuild, mean SAH
// drift, per-set mean rates and their share of the rebuilt tree's, the
// overall share, the worst agreement, mean update + diffuse trace.
void print_summary_row(std::ostream& out, const std::string& label, const Totals& t, bool has_sah,
                       const Totals* embree_refit, int wins) {
    out << padl(label, 16);
    if (t.frames == 0) {
        out << "  n/a\n";
        return;
    }
    const double n = double(t.frames);
    out << pad(fmt("%.2f", t.update_ms / n), 11) << pad(fmt("%.2fx", t.rebuild_ms / t.update_ms), 12)
        << pad(has_sah ? fmt("%+.1f%%", 100.0 * (t.sah / t.rebuilt_sah - 1.0)) : "-", 8);
    double ours = 0.0, theirs = 0.0;
    for (size_t s = 0; s < t.rays.size(); ++s) {
        out << pad(rate_cell(t.rays[s], t.trace_ms[s], t.rebuilt_trace_ms[s]), 16);
        ours += t.trace_ms[s];
        theirs += t.rebuilt_trace_ms[s];
    }
    out << pad(fmt("%.0f%%", 100.0 * theirs / ours), 8) << pad(fmt("%.4f", t.agreement), 8);
    if (t.diffuse_set >= 0) {
        out << pad(fmt("%.1f", t.diffuse_total_ms / n), 13);
        if (embree_refit && embree_refit->frames > 0)
            out << pad(fmt("%.2fx", embree_refit->diffuse_total_ms / t.diffuse_total_ms), 10)
                << pad(std::to_string(wins) + "/" + std::to_string(t.frames), 8);
    }
    out << '\n';
}

// The run's sums per structure, and per method the frames where update +
// diffuse trace beat Embree refit's.
struct Summary {
    Totals rebuilt;
    std::vector<Totals> methods, peers;
    std::vector<int> wins;
    int refit_peer = -1;
};

void add_method_frame(Summary& sum, size_t m, const AnimateFrame& f, int diffuse) {
    const MethodFrame& mf = f.methods[m];
    if (!mf.ok) return;
    Totals& t = sum.methods[m];
    add_frame(t, f, mf.update_ms, mf.traces, diffuse);
    t.sah += mf.stats.sah_cost;
    t.counts.refitted_nodes += mf.stats.refitted_nodes;
    t.counts.rebuilt_subtrees += mf.stats.rebuilt_subtrees;
    t.counts.rebuilt_nodes += mf.stats.rebuilt_nodes;
    t.counts.migrations += mf.stats.migrations;
    t.counts.meshes_updated += mf.stats.meshes_updated;
    if (sum.refit_peer < 0 || diffuse < 0) return;
    const PeerFrame& refit = f.embree[size_t(sum.refit_peer)];
    const size_t d = size_t(diffuse);
    if (refit.ok && mf.update_ms + mf.traces.trace_ms[d] < refit.update_ms + refit.traces.trace_ms[d]) ++sum.wins[m];
}

Summary summarise(const AnimateResult& r, int diffuse) {
    Summary sum;
    sum.methods.resize(r.methods.size());
    sum.peers.resize(r.embree.size());
    sum.wins.assign(r.methods.size(), 0);
    for (size_t p = 0; p < r.embree.size(); ++p)
        if (r.embree[p].update == EmbreeUpdate::Refit) sum.refit_peer = int(p);
    for (const AnimateFrame& f : r.frames) {
        add_frame(sum.rebuilt, f, f.rebuild_ms, FrameTraces{f.rebuild_trace_ms, 1.0}, diffuse);
        sum.rebuilt.sah += f.rebuild_sah;
        for (size_t p = 0; p < f.embree.size(); ++p)
            if (f.embree[p].ok) add_frame(sum.peers[p], f, f.embree[p].update_ms, f.embree[p].traces, diffuse);
        for (size_t m = 0; m < f.methods.size(); ++m) add_method_frame(sum, m, f, diffuse);
    }
    return sum;
}

void print_summary(std::ostream& out, const AnimateResult& r) {
    const int diffuse = diffuse_index(r);
    const Summary sum = summarise(r, diffuse);
    const Totals& rebuilt = sum.rebuilt;
    const std::vector<Totals>& methods = sum.methods;
    const std::vector<Totals>& peers = sum.peers;
    const int refit_peer = sum.refit_peer;
    const std::vector<int>& wins = sum.wins;
    out << "\n-- averages over " << r.frames.size() << " frames (" << r.scene << ")\n"
        << padl("structure", 16) << pad("update ms", 11) << pad("vs rebuild", 12) << pad("SAH", 8);
    for (RaySetKind kind : r.ray_sets) out << pad(ray_set_name(kind), 16);
    out << pad("trace", 8) << pad("agree", 8);
    if (diffuse >= 0) out << pad("+diffuse ms", 13) << pad("vs refit", 10) << pad("wins", 8);
    out << '\n';
    print_summary_row(out, "rebuild (full)", rebuilt, true, nullptr, 0);
    const Totals* embree_refit = refit_peer >= 0 ? &peers[size_t(refit_peer)] : nullptr;
    for (size_t m = 0; m < r.methods.size(); ++m)
        print_summary_row(out, to_string(r.methods[m].method), methods[m], true, embree_refit, wins[m]);
    for (size_t p = 0; p < r.embree.size(); ++p)
        print_summary_row(out, std::string("embree ") + embree_update_name(r.embree[p].update), peers[p], false,
                          nullptr, 0);
    for (size_t m = 0; m < r.methods.size(); ++m) {
        const Totals& t = methods[m];
        if (r.methods[m].method != UpdateMethod::Adapt || t.frames == 0) continue;
        const double n = double(t.frames);
        out << "adapt per frame (mean): " << fmt("%.0f", double(t.counts.refitted_nodes) / n) << " nodes refitted, "
            << fmt("%.1f", double(t.counts.rebuilt_subtrees) / n) << " subtrees rebuilt ("
            << fmt("%.0f", double(t.counts.rebuilt_nodes) / n) << " nodes), "
            << fmt("%.1f", double(t.counts.migrations) / n) << " migrations\n";
    }
    out << "(update ms: the structure's update in World::set_time (UpdateStats::update_ms: refit, restructure "
           "and layout, without the SAH reporting), or Embree's commits; vs rebuild: the full rebuild's "
           "time over it; SAH: mean drift against the rebuilt tree; trace: the rebuilt tree's trace time over "
           "this one's, all sets; +diffuse ms: update + the diffuse set; vs refit / wins: Embree refit's update + "
           "diffuse over ours, frames where ours is faster)\n";
}

}  // namespace

void print_animate_tables(std::ostream& out, const AnimateResult& result) {
    print_header(out, result);
    for (size_t m = 0; m < result.methods.size(); ++m) print_method_frames(out, result, m);
    print_peer_frames(out, result);
    if (!result.frames.empty()) print_summary(out, result);
}

namespace {

Json traces_json(const FrameTraces& t) { return {{"trace_ms", t.trace_ms}, {"agreement", t.agreement}}; }

Json frame_json(const AnimateResult& r, const AnimateFrame& f) {
    Json frame = {{"frame", f.frame},           {"time", f.time},
                  {"scene_ms", f.scene_ms},     {"rebuild_ms", f.rebuild_ms},
                  {"rebuild_sah", f.rebuild_sah}, {"rays", f.rays},
                  {"rebuild_trace_ms", f.rebuild_trace_ms}};
    Json methods = Json::object();
    for (size_t m = 0; m < f.methods.size(); ++m) {
        const MethodFrame& mf = f.methods[m];
        Json j = {{"ok", mf.ok}};
        if (!mf.ok) j["error"] = mf.error;
        else {
            j.update(traces_json(mf.traces));
            j.update({{"update_ms", mf.update_ms},
                      {"reported_update_ms", mf.stats.update_ms},
                      {"layout_ms", mf.stats.layout_ms},
                      {"sah_cost", mf.stats.sah_cost},
                      {"refitted_nodes", mf.stats.refitted_nodes},
                      {"rebuilt_subtrees", mf.stats.rebuilt_subtrees},
                      {"rebuilt_nodes", mf.stats.rebuilt_nodes},
                      {"migrations", mf.stats.migrations},
                      {"meshes_updated", mf.stats.meshes_updated}});
        }
        methods[to_string(r.methods[m].method)] = j;
    }
    frame["methods"] = methods;
    Json peers = Json::object();
    for (size_t p = 0; p < f.embree.size(); ++p) {
        const PeerFrame& pf = f.embree[p];
        Json j = {{"ok", pf.ok}};
        if (!pf.ok) j["error"] = pf.error;
        else {
            j.update(traces_json(pf.traces));
            j.update({{"update_ms", pf.update_ms}, {"copy_ms", pf.copy_ms}});
        }
        peers[embree_update_name(r.embree[p].update)] = j;
    }
    frame["embree"] = peers;
    return frame;
}

}  // namespace

void write_animate_json(const std::string& path, const std::vector<AnimateResult>& results,
                        const std::string& command) {
    const MachineInfo machine = machine_info();
    Json root = {{"command", command},
                 {"machine", {{"cpu", machine.cpu}, {"cores", machine.cores}}},
                 {"embree", embree_version()}};
    Json list = Json::array();
    for (const AnimateResult& r : results) {
        Json sets = Json::array();
        for (RaySetKind kind : r.ray_sets) sets.push_back(ray_set_name(kind));
        Json methods = Json::array(), peers = Json::array(), frames = Json::array();
        for (const MethodColumn& c : r.methods)
            methods.push_back({{"method", to_string(c.method)}, {"ok", c.ok}, {"error", c.error},
                               {"initial_build_ms", c.initial_build_ms}});
        for (const PeerColumn& c : r.embree)
            peers.push_back({{"update", embree_update_name(c.update)}, {"ok", c.ok}, {"error", c.error},
                             {"build_ms", c.build_ms}});
        for (const AnimateFrame& f : r.frames) frames.push_back(frame_json(r, f));
        list.push_back({{"scene", r.scene}, {"triangles", r.triangles}, {"frame_count", r.frame_count},
                        {"threads", r.threads}, {"build", r.build}, {"ray_sets", sets},
                        {"build_frame", r.build_frame}, {"methods", methods}, {"embree", peers},
                        {"frames", frames}});
    }
    root["results"] = list;
    std::ofstream out(path);
    if (!out) throw Error(path + ": cannot open for writing");
    out << root.dump(1) << '\n';
    if (!out) throw Error(path + ": write failed");
}

// --- ch. 3's Table 3.1 ---

namespace {

template <class F>
std::vector<double> runs_of(int repetitions, F&& f) {
    std::vector<double> runs;
    for (int r = 0; r < std::max(1, repetitions); ++r) runs.push_back(f());
    return runs;
}

// `candidate` and `base` traced alternately, `repetitions` rounds over
// every set: the candidate's median per set and the median over rounds of
// its total time over the base's. Pairing the rounds keeps the ratio from
// following the machine's load, which drifts between rows minutes apart.
struct PairedTraces {
    FrameTraces candidate;
    double ratio = 1.0;
};

PairedTraces paired_traces(const Accel& candidate, const Accel& base, const std::vector<RaySet>& sets,
                           int repetitions, const SetAnswers& reference) {
    PairedTraces out;
    std::vector<std::vector<double>> per_set(sets.size());
    std::vector<double> ratios;
    for (int r = 0; r < std::max(1, repetitions); ++r) {
        const FrameTraces c = trace_sets(candidate, sets, 1, &reference, nullptr);
        const FrameTraces b = trace_sets(base, sets, 1, nullptr, nullptr);
        double c_total = 0.0, b_total = 0.0;
        for (size_t s = 0; s < sets.size(); ++s) {
            per_set[s].push_back(c.trace_ms[s]);
            c_total += c.trace_ms[s];
            b_total += b.trace_ms[s];
        }
        ratios.push_back(b_total > 0.0 ? c_total / b_total : 1.0);
        out.candidate.agreement = std::min(out.candidate.agreement, c.agreement);
    }
    for (const std::vector<double>& runs : per_set) out.candidate.trace_ms.push_back(median(runs));
    out.ratio = median(ratios);
    return out;
}

// Box and triangle tests per ray of `rays` (closest hit); zeros when the accel does not count.
void count_work(const Accel& accel, const std::vector<Ray>& rays, ClusterRow& row) {
    TraversalTotals totals;
    if (rays.empty() || !accel.count_traversal(rays, false, totals) || totals.rays == 0) return;
    row.steps_per_ray = double(totals.steps) / double(totals.rays);
    row.tests_per_ray = double(totals.prim_tests) / double(totals.rays);
}

// `acc`: the plain Acc row of the same size, whose partition this row's
// equals (subtrees; Naive merging stops at Acc's count): its cluster count is
// reused and the setup is timed from the accel's first build, so the
// 800K-triangle tables cluster once less per row.
ClusterRow cluster_row(LoadedScene& scene, int size, ClusterHeuristic heuristic, bool subtrees,
                       const ClusterTableConfig& config, const std::vector<RaySet>& sets, const SetAnswers& reference,
                       const Accel& base, const ClusterRow* acc) {
    ClusterRow row;
    row.size = size;
    row.heuristic = heuristic;
    row.subtrees = subtrees;
    UpdateOptions update;
    update.method = UpdateMethod::Clusters;
    update.clusters.heuristic = heuristic;
    update.clusters.generation = config.generation;
    update.clusters.max_count = size;
    update.clusters.max_size = float(size);
    update.clusters.cluster_subtrees = subtrees;
    BuildOptions build = config.build;
    build.threads = config.threads;
    try {
        const bool reuse = acc && acc->ok && (subtrees || config.generation == ClusterGeneration::Merge);
        if (!reuse) {  // the clustering alone, timed as the accel runs it (the same partition)
            const auto start = Clock::now();
            row.clusters = cluster_scene(scene.scene, scene.geometry, update.clusters).size();
            row.clustering_ms = ms_since(start);
        }
        const std::unique_ptr<DynamicAccel> accel = build_dynamic_accel(scene.scene, scene.geometry, build, update);
        const GeometryChange all = everything(scene.scene);
        std::vector<double> canonical;  // the per-frame build without the layout (the first build has none)
        row.build_ms = median(runs_of(config.repetitions, [&] {
            const UpdateStats stats = accel->update(all);
            canonical.push_back(stats.update_ms - stats.layout_ms);
            return stats.update_ms;
        }));
        if (reuse) {
            row.clusters = acc->clusters;
            row.clustering_ms = std::max(0.0, accel->initial_build_ms() - median(canonical));
        }
        const PairedTraces traces = paired_traces(*accel, base, sets, config.repetitions, reference);
        row.primary_ms = traces.candidate.trace_ms[0];
        row.diffuse_ms = traces.candidate.trace_ms[1];
        row.trace_ratio = traces.ratio;
        row.agreement = traces.candidate.agreement;
        count_work(*accel, sets[1].rays, row);
        row.ok = true;
    } catch (const std::exception& e) {
        row.error = first_line(e);
    }
    return row;
}

}  // namespace

ClusterTable run_cluster_table(LoadedScene& scene, const ClusterTableConfig& config, std::ostream& log) {
    ClusterTable table;
    table.scene = scene.spec.name;
    table.triangles = scene.geometry.size();
    table.vertices = scene.scene.vertex_count();
    BuildOptions build = config.build;
    build.threads = config.threads;
    parallel::with_threads(config.threads, [&] {
        if (scene.scene.animated()) go_to_frame(scene, 0);
        if (config.progress) log << scene.spec.name << ": cluster table, triangle build\n" << std::flush;
        std::unique_ptr<Accel> base;
        const std::vector<double> builds = runs_of(config.repetitions, [&] {
            const auto start = Clock::now();
            base = build_accel(scene.geometry, build);
            return ms_since(start);
        });
        const ViewSetup view = make_view_setup(scene, 0, config.width, config.height);
        const std::vector<RaySet> sets = make_ray_sets(scene.geometry, *base, view, {RaySetKind::Primary, RaySetKind::Diffuse});
        table.primary_rays = sets[0].rays.size();
        table.diffuse_rays = sets[1].rays.size();
        SetAnswers reference;
        const FrameTraces traces = trace_sets(*base, sets, config.repetitions, nullptr, &reference);
        ClusterRow none;
        none.ok = true;
        none.clusters = table.triangles;
        none.build_ms = median(builds);
        none.primary_ms = traces.trace_ms[0];
        none.diffuse_ms = traces.trace_ms[1];
        count_work(*base, sets[1].rays, none);
        for (int size : config.sizes) {
            if (size <= 0) {
                table.rows.push_back(none);
                continue;
            }
            for (ClusterHeuristic heuristic : config.heuristics) {
                if (config.progress)
                    log << scene.spec.name << ": cluster table, " << to_string(heuristic) << ' ' << size << '/' << size
                        << '\n' << std::flush;
                const ClusterRow* acc = nullptr;
                for (const ClusterRow& r : table.rows)
                    if (r.size == size && r.heuristic == ClusterHeuristic::Acc && !r.subtrees) acc = &r;
                table.rows.push_back(cluster_row(scene, size, heuristic, false, config, sets, reference, *base, acc));
            }
            if (size == config.subtree_size) {
                if (config.progress)
                    log << scene.spec.name << ": cluster table, acc+subtrees " << size << '/' << size << '\n' << std::flush;
                const ClusterRow* acc = nullptr;
                for (const ClusterRow& r : table.rows)
                    if (r.size == size && r.heuristic == ClusterHeuristic::Acc && !r.subtrees) acc = &r;
                table.rows.push_back(cluster_row(scene, size, ClusterHeuristic::Acc, true, config, sets, reference, *base, acc));
            }
        }
    });
    return table;
}

void print_cluster_tables(std::ostream& out, const std::vector<ClusterTable>& tables, int threads) {
    for (const ClusterTable& t : tables) {
        out << "\n== " << t.scene << " (" << thousands(t.triangles) << " triangles, " << thousands(t.vertices)
            << " vertices): ch. 3 Table 3.1, " << threads << " threads; " << thousands(t.primary_rays)
            << " primary, " << thousands(t.diffuse_rays) << " diffuse rays\n"
            << pad("MaxCount=MaxSize", 17) << pad("heuristic", 10) << pad("clustering ms", 15) << pad("clusters", 11)
            << pad("build ms", 10) << pad("speed-up", 10) << pad("primary ms", 12) << pad("diffuse ms", 12)
            << pad("vs tris", 9) << pad("steps/ray", 11) << pad("tests/ray", 11) << pad("agree", 8) << '\n';
        const ClusterRow* none = nullptr;
        for (const ClusterRow& row : t.rows)
            if (row.size == 0) none = &row;
        const auto count_cell = [](double v) { return v > 0.0 ? fmt("%.1f", v) : std::string("-"); };
        for (const ClusterRow& row : t.rows) {
            out << pad(row.size == 0 ? "0 (triangles)" : std::to_string(row.size) + "/" + std::to_string(row.size), 17)
                << pad(row.size == 0 ? "-" : to_string(row.heuristic) + (row.subtrees ? "+sub" : ""), 10);
            if (!row.ok) {
                out << "  n/a (" << row.error << ")\n";
                continue;
            }
            out << pad(fmt("%.1f", row.clustering_ms), 15) << pad(row.clusters ? thousands(row.clusters) : "-", 11)
                << pad(fmt("%.2f", row.build_ms), 10)
                << pad(none ? fmt("%.2fx", none->build_ms / row.build_ms) : "-", 10) << pad(fmt("%.1f", row.primary_ms), 12)
                << pad(fmt("%.1f", row.diffuse_ms), 12)
                << pad(fmt("%+.1f%%", 100.0 * (row.trace_ratio - 1.0)), 9) << pad(count_cell(row.steps_per_ray), 11)
                << pad(count_cell(row.tests_per_ray), 11) << pad(fmt("%.4f", row.agreement), 8) << '\n';
        }
    }
    if (!tables.empty())
        out << "(clustering ms: the one-time clustering (cluster_scene; for naive and +sub rows, which reuse acc's "
               "partition: the accel's first build less a per-frame build, so +sub includes its subtrees' SAH builds); "
               "+sub: ClusterOptions::cluster_subtrees; build ms: the per-frame build, median; vs tris: primary + diffuse trace time against the "
               "triangle build's, the median of per-round ratios with the two traced alternately; steps/ray, tests/ray: "
               "box and triangle tests per diffuse ray)\n";
}

}  // namespace rf::bench
