// `rayforge bench --paged`: a paged scene traced from budgeted page caches
// against the same quantised geometry in core (Garanzha 2014, §6.7.2-6.7.4,
// tables 6.3/6.4). Per file:
//   1. the caches' sizes: two probe opens measure each manager's fixed
//      tables and bytes per slot, so that a fraction f of the scene becomes
//      explicit per-manager budgets of round(f * pages) slots (f = 1 holds
//      every page; at least one slot, and 16 texture tiles; the texture
//      cache's shards make its budget a search of a few opens);
//   2. the ray sets, made once in core (a BVH8 over decode_paged_geometry):
//      primary (pixel centres of the file's camera), shadow (towards the
//      file's first light), diffuse bounces 1..3 (cosine-sampled about the
//      hit triangle's geometric normal, fixed seed), each timed in core with
//      Accel::time_traversal as it is made; the in-core answers are kept
//      (paged primitive ids) and the in-core structure freed;
//   3. per budget, a fresh PagedScene: each ray set traced once from empty
//      caches (cold), once more to warm up, then --reps times warm (a
//      running renderer's caches are warm: Garanzha 2014 measures its
//      iterations), with the caches' and query loop's counts as deltas
//      around the runs; then the paged path tracer (3 bounces) from empty
//      caches, pass by pass (the first pass cold).
// Public API only (no src/ header): the figures are what a user of
// rf::PagedScene can see.
#include "paged_bench.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include "bench_report.h"
#include "ray_sets.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/world.h"

namespace rf::bench {
namespace {

using Clock = std::chrono::steady_clock;
using Json = nlohmann::json;

constexpr uint32_t kDiffuseSeed = 0x5EED0006u;  // the diffuse bounces' directions; never changes
constexpr int kDiffuseBounces = 3;
constexpr uint32_t kTextureMinSlots = 16;        // the texture cache refuses fewer tiles

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

double median(std::vector<double> values) {
    if (values.empty()) return 0.0;
    std::sort(values.begin(), values.end());
    const size_t n = values.size();
    return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

std::string format(const char* fmt, double value) {
    if (!std::isfinite(value)) return "-";
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), fmt, value);
    return buffer;
}

// Right-aligned columns keep a space before an overlong value.
std::string pad(const std::string& text, size_t width, bool left = false) {
    if (text.size() >= width) return left ? text : ' ' + text;
    return left ? text + std::string(width - text.size(), ' ') : std::string(width - text.size(), ' ') + text;
}

std::string megabytes(double bytes) { return format(bytes < 10e6 ? "%.2f MB" : "%.1f MB", bytes / 1e6); }

std::string budget_label(double f) {
    if (f >= 1.0) return "1";
    const double inverse = 1.0 / f;
    if (std::fabs(inverse - std::round(inverse)) < 1e-6) return "1/" + std::to_string(int(std::round(inverse)));
    return format("%g", f);
}

// ---- Random directions (the diffuse bounces) ------------------------------

// PCG hash (Jarzynski and Olano 2020): a well-mixed 32-bit value.
uint32_t pcg_hash(uint32_t v) {
    const uint32_t state = v * 747796405u + 2891336453u;
    const uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Number `dim` of path `path` at bounce `bounce`, in [0, 1).
float uniform(uint32_t path, uint32_t bounce, uint32_t dim) {
    const uint32_t h = pcg_hash(pcg_hash(pcg_hash(path ^ kDiffuseSeed) + bounce) + dim);
    return float(h >> 8) * (1.0f / 16777216.0f);
}

// A cosine-weighted direction about the unit normal n (frame of Duff et al. 2017).
Vec3f cosine_direction(Vec3f n, float u1, float u2) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z), b = n.x * n.y * a;
    const Vec3f t{1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x};
    const Vec3f s{b, sign + n.y * n.y * a, -n.y};
    const float r = std::sqrt(u1), phi = 6.28318531f * u2;
    return normalize(t * (r * std::cos(phi)) + s * (r * std::sin(phi)) + n * std::sqrt(std::max(0.0f, 1.0f - u1)));
}

// ---- The ray sets, made and timed in core ----------------------------------

// One ray set with the in-core answers, as paged primitive ids (closest
// hits) or occlusion flags (shadow rays).
struct TracedSet {
    std::string name;
    bool any_hit = false;
    std::vector<Ray> rays;
    std::vector<uint32_t> paths;          // the primary pixel of each ray (the diffuse seed)
    std::vector<uint32_t> expected_prim;  // closest hit: paged primitive id or kInvalidId
    std::vector<uint8_t> expected_occluded;
    uint64_t in_core_hits = 0;
    double in_core_mrays_per_s = 0.0;
};

// Everything the in-core side needs while the sets are made.
struct InCore {
    DecodedPagedGeometry decoded;
    std::unique_ptr<Accel> accel;
    float offset = 0.0f;  // secondary origins leave the surface by this much (1e-4 x the scene's diagonal)
    int repetitions = 5;
};

// Times `set` in core (a warm-up and the runs) and keeps the answers.
std::vector<Hit> trace_in_core(const InCore& core, TracedSet& set) {
    std::vector<Hit> hits(set.any_hit ? 0 : set.rays.size());
    std::vector<uint8_t> occluded(set.any_hit ? set.rays.size() : 0);
    const std::vector<double> times = core.accel->time_traversal(set.rays, set.any_hit, core.repetitions, hits, occluded);
    const double ms = median(times);
    set.in_core_mrays_per_s = ms > 0.0 ? double(set.rays.size()) / (ms * 1e3) : 0.0;
    if (set.any_hit) {
        set.expected_occluded = occluded;
        set.in_core_hits = uint64_t(std::count(occluded.begin(), occluded.end(), uint8_t(1)));
        return hits;
    }
    set.expected_prim.resize(hits.size());
    for (size_t i = 0; i < hits.size(); ++i) {
        set.expected_prim[i] = hits[i].found() ? core.decoded.prims[hits[i].prim] : kInvalidId;
        set.in_core_hits += hits[i].found() ? 1 : 0;
    }
    return hits;
}

// Where a secondary ray leaves the surface a ray hit, and the unit geometric
// normal there facing that ray.
struct SurfacePoint {
    Vec3f origin, normal;
};

SurfacePoint surface_point(const InCore& core, const Ray& ray, const Hit& hit) {
    Vec3f n = core.decoded.geometry.triangles[hit.prim].geometric_normal();
    const float len = length(n);
    n = len > 0.0f ? n * (1.0f / len) : Vec3f(0, 0, 1);
    if (dot(n, ray.dir) > 0.0f) n = -n;
    return {ray.org + ray.dir * hit.t + n * core.offset, n};
}

// A ray from `p` towards the light (any hit).
Ray shadow_ray(const SurfacePoint& p, const Light& light) {
    Ray ray;
    ray.org = p.origin;
    if (light.type == LightType::Directional) {
        ray.dir = normalize(-light.direction);
        return ray;
    }
    const Vec3f to_light = light.position - p.origin;
    const float distance = length(to_light);
    ray.dir = to_light * (1.0f / std::max(distance, 1e-30f));
    ray.tmax = distance * (1.0f - 1e-4f);
    return ray;
}

TracedSet make_shadow_set(const InCore& core, const TracedSet& primary, const std::vector<Hit>& hits,
                          const Light& light) {
    TracedSet set;
    set.name = "shadow";
    set.any_hit = true;
    for (size_t i = 0; i < hits.size(); ++i) {
        if (!hits[i].found()) continue;
        set.rays.push_back(shadow_ray(surface_point(core, primary.rays[i], hits[i]), light));
        set.paths.push_back(primary.paths[i]);
    }
    return set;
}

// Bounce `bounce` (1..3): one cosine-sampled ray from each hit of the previous set.
TracedSet make_diffuse_set(const InCore& core, const TracedSet& previous, const std::vector<Hit>& hits, int bounce) {
    TracedSet set;
    set.name = "diffuse" + std::to_string(bounce);
    for (size_t i = 0; i < hits.size(); ++i) {
        if (!hits[i].found()) continue;
        const SurfacePoint p = surface_point(core, previous.rays[i], hits[i]);
        const uint32_t path = previous.paths[i];
        Ray ray;
        ray.org = p.origin;
        ray.dir = cosine_direction(p.normal, uniform(path, uint32_t(bounce), 0), uniform(path, uint32_t(bounce), 1));
        set.rays.push_back(ray);
        set.paths.push_back(path);
    }
    return set;
}

TracedSet make_primary_set(const Camera& camera, int width, int height) {
    ViewSetup view;
    view.camera = camera;
    view.width = width;
    view.height = height;
    TracedSet set;
    set.name = "primary";
    set.rays = make_primary_rays(view).rays;  // pixel centres, row-major
    set.paths.resize(set.rays.size());
    for (size_t i = 0; i < set.paths.size(); ++i) set.paths[i] = uint32_t(i);
    return set;
}

// The decoded pages in core, a BVH8 over them, and every ray set made and
// timed on it. The in-core structure is freed on return.
std::vector<TracedSet> make_ray_sets(const std::string& path, const Camera& camera, const std::optional<Light>& light,
                                     const PagedBenchConfig& config, PagedFileSummary& summary, std::ostream& log) {
    InCore core;
    core.repetitions = config.repetitions;
    core.decoded = decode_paged_geometry(path);
    summary.in_core_triangles = core.decoded.geometry.size();
    core.offset = 1e-4f * length(core.decoded.geometry.bounds.extent());
    BuildOptions build;  // bvh / binned / bvh8
    build.threads = config.threads;
    const Clock::time_point start = Clock::now();
    core.accel = build_accel(core.decoded.geometry, build);
    summary.in_core_build_ms = ms_since(start);
    log << "paged bench: " << path << ": in core " << core.accel->stats().name << " over "
        << thousands(summary.in_core_triangles) << " decoded triangles (" << format("%.0f", summary.in_core_build_ms)
        << " ms); tracing the ray sets in core\n";

    std::vector<TracedSet> sets;
    sets.push_back(make_primary_set(camera, config.width, config.height));
    const std::vector<Hit> primary_hits = trace_in_core(core, sets.back());
    if (light) {
        sets.push_back(make_shadow_set(core, sets.front(), primary_hits, *light));
        trace_in_core(core, sets.back());
    }
    std::vector<Hit> hits = primary_hits;
    size_t previous = 0;
    for (int bounce = 1; bounce <= kDiffuseBounces; ++bounce) {
        TracedSet next = make_diffuse_set(core, sets[previous], hits, bounce);
        sets.push_back(std::move(next));
        previous = sets.size() - 1;
        hits = trace_in_core(core, sets.back());
    }
    return sets;
}

// ---- Cache budgets ---------------------------------------------------------

// A manager's memory as a function of its slots, from two probe opens:
// fixed + per_slot * slots is exact for the geometry and attribute managers
// (tables per page, bookkeeping per slot). The texture tiles' shards add
// steps, so their budget starts from an upper bound (the first probe's
// memory less the pages it needs not hold) and is then tightened.
struct ManagerModel {
    std::string name;
    uint32_t pages = 0, min_slots = 1;
    size_t slot_bytes = 0;
    double fixed = 0.0, per_slot = 0.0;
    bool linear = true;                 // false: textures
    uint32_t probe_slots = 0;           // the first probe's
    size_t probe_memory = 0;

    // A budget that holds `slots` slots (half a slot of slack against rounding).
    [[nodiscard]] size_t bytes_for(uint32_t slots) const {
        if (pages == 0) return 1;
        if (!linear && slots <= probe_slots) return probe_memory - size_t(probe_slots - slots) * slot_bytes;
        return size_t(std::ceil(fixed + per_slot * (double(slots) + 0.5)));
    }
};

struct Budgets {
    size_t bytes[3] = {0, 0, 0};  // geometry, attributes, textures
};

// A paged world with these cache budgets (the path tracer renders worlds).
std::unique_ptr<World> open_with(const std::string& path, const Budgets& b, int threads) {
    WorldOptions world;
    PagedSceneOptions& options = world.paged;
    options.geometry_budget = std::max<size_t>(b.bytes[0], 1);
    options.attribute_budget = std::max<size_t>(b.bytes[1], 1);
    options.texture_budget = std::max<size_t>(b.bytes[2], 1);
    options.memory_budget = options.geometry_budget + options.attribute_budget + options.texture_budget;
    options.threads = threads;
    try {
        return open_world(path, world);
    } catch (const std::bad_alloc&) {
        throw Error(path + ": page caches of " + megabytes(double(options.memory_budget)) +
                    " could not be allocated (use smaller --budgets)");
    }
}

// The first probe: the default split of 256 MiB (4 GiB when the page
// tables of a huge file do not fit in that).
std::unique_ptr<PagedScene> open_probe(const std::string& path, int threads) {
    PagedSceneOptions options;
    options.threads = threads;
    for (const size_t total : {size_t(256) << 20, size_t(4) << 30}) {
        options.memory_budget = total;
        try {
            return open_paged_scene(path, options);
        } catch (const Error&) {
            if (total == (size_t(4) << 30)) throw;
        }
    }
    return nullptr;
}

// The file's first light: the shadow set aims at it (or at --light-dir).
std::optional<Light> file_light(const PagedScene& scene) {
    const std::vector<Light> lights = scene.lights();
    if (lights.empty()) return std::nullopt;
    return lights.front();
}

// What the probe opens learn about a file.
struct FileProbe {
    std::vector<ManagerModel> models;  // geometry, attributes, textures
    PagedSceneInfo info;
    Camera camera;
    std::optional<Light> light;
};

FileProbe probe_file(const std::string& path, int threads) {
    FileProbe probe;
    std::vector<PageCacheReport> first;
    {
        const std::unique_ptr<PagedScene> scene = open_probe(path, threads);
        first = scene->caches();
        probe.info = scene->info();
        probe.camera = scene->camera();
        probe.light = file_light(*scene);
    }
    if (first.size() != 3) throw Error(path + ": expected 3 page managers, the scene reports " +
                                       std::to_string(first.size()));
    probe.models.resize(3);
    Budgets half;  // about half the first probe's slots, where it had a few
    for (size_t k = 0; k < 3; ++k) {
        const PageCacheReport& c = first[k];
        ManagerModel& m = probe.models[k];
        m.name = c.name;
        m.pages = c.pages;
        m.slot_bytes = c.slot_bytes;
        m.linear = c.name != "textures";
        m.min_slots = m.linear ? std::min(1u, c.pages) : std::min(kTextureMinSlots, c.pages);
        m.probe_slots = c.slots;
        m.probe_memory = c.memory_bytes;
        const uint32_t fewer = std::max(m.min_slots, c.slots / 2);
        half.bytes[k] = c.slots >= 4 && fewer < c.slots ? c.memory_bytes - size_t(c.slots - fewer) * c.slot_bytes
                                                        : c.budget_bytes;
    }
    const std::vector<PageCacheReport> second = open_with(path, half, threads)->paged_scene().caches();
    for (size_t k = 0; k < 3; ++k) {
        const PageCacheReport &a = first[k], &b = second[k];
        ManagerModel& m = probe.models[k];
        m.per_slot = a.slots > b.slots ? double(a.memory_bytes - b.memory_bytes) / double(a.slots - b.slots)
                                       : double(a.slot_bytes);
        m.fixed = double(a.memory_bytes) - m.per_slot * double(a.slots);
    }
    return probe;
}

uint32_t target_slots(const ManagerModel& m, double f, bool* clamped) {
    const double wanted = std::round(f * double(m.pages));
    *clamped = wanted < double(m.min_slots);
    return uint32_t(std::clamp(wanted, double(m.min_slots), double(m.pages)));
}

// Fewer texture slots while the cache holds more than `target` (the budget
// started from an upper bound): at most two smaller opens, each kept only
// when it still holds the target.
void tighten_textures(const std::string& path, const ManagerModel& m, uint32_t target, int threads, Budgets& budgets,
                      std::unique_ptr<World>& scene) {
    for (int step = 0; step < 2; ++step) {
        const uint32_t slots = scene->paged_scene().caches()[2].slots;
        if (slots <= target) return;
        Budgets trial = budgets;
        trial.bytes[2] -= std::min(trial.bytes[2] - 1, size_t(slots - target) * m.slot_bytes);
        try {
            std::unique_ptr<World> smaller = open_with(path, trial, threads);
            if (smaller->paged_scene().caches()[2].slots < target) return;
            scene = std::move(smaller);
            budgets = trial;
        } catch (const Error&) {
            return;  // below the fewest tiles the cache accepts
        }
    }
}

// Opens `path` with caches of f of the scene: per manager the model's budget
// for round(f * pages) slots, raised and reopened (at most twice) where a
// manager made fewer slots, the textures' tightened where they made more.
std::unique_ptr<World> open_at_fraction(const std::string& path, const std::vector<ManagerModel>& models, double f,
                                        int threads, std::vector<PagedCacheFigures>& figures) {
    Budgets budgets;
    uint32_t targets[3] = {0, 0, 0};
    figures.assign(3, {});
    for (size_t k = 0; k < 3; ++k) {
        figures[k].name = models[k].name;
        targets[k] = target_slots(models[k], f, &figures[k].clamped);
        budgets.bytes[k] = models[k].bytes_for(targets[k]);
    }
    std::unique_ptr<World> scene;
    for (int attempt = 0; attempt < 3; ++attempt) {
        scene = open_with(path, budgets, threads);
        const std::vector<PageCacheReport> caches = scene->paged_scene().caches();
        bool short_of_slots = false;
        for (size_t k = 0; k < 3; ++k) {
            if (caches[k].slots >= targets[k]) continue;
            short_of_slots = true;
            budgets.bytes[k] += size_t(double(targets[k] - caches[k].slots + 1) * models[k].per_slot) + (size_t(1) << 19);
        }
        if (!short_of_slots) break;
    }
    if (!models[2].linear) tighten_textures(path, models[2], targets[2], threads, budgets, scene);
    const std::vector<PageCacheReport> caches = scene->paged_scene().caches();
    for (size_t k = 0; k < 3; ++k) {
        figures[k].pages = caches[k].pages;
        figures[k].slots = caches[k].slots;
        figures[k].budget_bytes = caches[k].budget_bytes;
    }
    return scene;
}

// ---- Paged runs --------------------------------------------------------------

// The caches' and query loop's counts since the last reset_stats, over `runs` runs.
void collect_counts(const PagedScene& scene, const std::vector<double>& run_ms, uint64_t rays_per_run,
                    PagedRunFigures& out) {
    out.runs = int(run_ms.size());
    out.ms = median(run_ms);
    const double runs = std::max(1.0, double(run_ms.size()));
    for (double ms : run_ms) out.mean_ms += ms / runs;
    const double rays = double(rays_per_run) * runs;
    out.mrays_per_s = out.ms > 0.0 ? double(rays_per_run) / (out.ms * 1e3) : 0.0;
    uint64_t bytes = 0;
    out.caches.clear();
    for (const PageCacheReport& c : scene.caches()) {
        PagedCacheFigures f;
        f.name = c.name;
        f.pages = c.pages;
        f.slots = c.slots;
        f.budget_bytes = c.budget_bytes;
        f.requests = c.requests;
        f.hits = c.hits;
        f.pages_read = c.pages_read;
        f.bytes_read = c.bytes_read;
        f.evictions = c.evictions;
        f.io_ms = c.io_ms;
        f.manage_ms = c.manage_ms;
        bytes += c.bytes_read;
        out.io_ms += c.io_ms / runs;
        out.manage_ms += c.manage_ms / runs;
        out.caches.push_back(f);
    }
    const PagedQueryStats q = scene.query_stats();
    out.bytes_per_ray = rays > 0 ? double(bytes) / rays : 0.0;
    out.traversal_ms = q.traversal_ms / runs;
    out.sort_ms = q.sort_ms / runs;
    out.iterations_per_loop = double(q.iterations) / runs;
    out.iterations_per_ray = q.queries ? double(q.ray_iterations) / double(q.queries) : 0.0;
}

// One batch through the paged accel, timed.
double trace_paged(const PagedScene& scene, const TracedSet& set, std::vector<Hit>& hits, std::vector<uint8_t>& occluded) {
    const Clock::time_point start = Clock::now();
    if (set.any_hit) scene.accel().occluded(set.rays, occluded);
    else scene.accel().intersect(set.rays, hits);
    return ms_since(start);
}

// The paged answers of the last run against the in-core ones.
void compare_answers(const TracedSet& set, const std::vector<Hit>& hits, const std::vector<uint8_t>& occluded,
                     PagedBenchRow& row) {
    uint64_t same = 0, found = 0;
    for (size_t i = 0; i < set.rays.size(); ++i) {
        if (set.any_hit) {
            found += occluded[i] ? 1 : 0;
            same += (occluded[i] != 0) == (set.expected_occluded[i] != 0) ? 1 : 0;
        } else {
            found += hits[i].found() ? 1 : 0;
            same += hits[i].prim == set.expected_prim[i] ? 1 : 0;
        }
    }
    row.paged_hits = found;
    row.in_core_hits = set.in_core_hits;
    row.agreement = set.rays.empty() ? 1.0 : double(same) / double(set.rays.size());
}

// A ray set at one budget: cold from empty caches, a warm-up, then the timed warm runs.
PagedBenchRow run_ray_set(PagedScene& scene, const TracedSet& set, double budget, const PagedBenchConfig& config) {
    PagedBenchRow row;
    row.file = scene.info().path;
    row.workload = set.name;
    row.budget = budget;
    row.rays = set.rays.size();
    std::vector<Hit> hits(set.any_hit ? 0 : set.rays.size());
    std::vector<uint8_t> occluded(set.any_hit ? set.rays.size() : 0);
    scene.clear_caches(config.cold_from_disk);
    scene.reset_stats();
    const double cold_ms = trace_paged(scene, set, hits, occluded);
    collect_counts(scene, {cold_ms}, row.rays, row.cold);
    // The warm-up: a loop from partly filled caches may still test (and
    // read) a page the cold loop's order let it skip.
    trace_paged(scene, set, hits, occluded);
    scene.reset_stats();
    std::vector<double> warm_ms;
    for (int r = 0; r < config.repetitions; ++r) warm_ms.push_back(trace_paged(scene, set, hits, occluded));
    collect_counts(scene, warm_ms, row.rays, row.warm);
    compare_answers(set, hits, occluded, row);
    row.in_core_mrays_per_s = set.in_core_mrays_per_s;
    row.slowdown = row.warm.mrays_per_s > 0.0 ? set.in_core_mrays_per_s / row.warm.mrays_per_s : 0.0;
    return row;
}

// The paged path tracer at one budget from empty caches: the first pass
// cold, the others warm (slowdown against f = 1 is filled in later).
PagedBenchRow run_path_tracing(World& world, const Camera& camera, double budget, const PagedBenchConfig& config) {
    PagedScene& scene = world.paged_scene();
    RenderOptions options;
    options.width = config.width;
    options.height = config.height;
    options.spp = config.passes;
    options.integrator = IntegratorKind::Path;
    options.max_depth = config.max_depth;
    options.threads = config.threads;
    scene.clear_caches(config.cold_from_disk);
    scene.reset_stats();
    const std::unique_ptr<Renderer> renderer = make_renderer(world, camera, options);
    PagedBenchRow row;
    row.file = scene.info().path;
    row.workload = "path";
    row.budget = budget;
    renderer->render_pass();
    const PassStats& first = renderer->last_pass();
    row.first_pass_ms = first.pass_ms;
    collect_counts(scene, {first.pass_ms}, first.closest_rays + first.shadow_rays, row.cold);
    scene.reset_stats();
    std::vector<double> pass_ms;
    uint64_t rays = 0;
    for (int p = 1; p < config.passes; ++p) {
        renderer->render_pass();
        pass_ms.push_back(renderer->last_pass().pass_ms);
        rays += renderer->last_pass().closest_rays + renderer->last_pass().shadow_rays;
    }
    row.rays = rays / uint64_t(pass_ms.size());
    collect_counts(scene, pass_ms, row.rays, row.warm);
    double total_ms = 0.0;
    for (double ms : pass_ms) total_ms += ms;
    row.warm.mrays_per_s = total_ms > 0.0 ? double(rays) / (total_ms * 1e3) : 0.0;
    return row;
}

// Path rows: slowdown = ms per pass / the fully cached (f = 1) run's.
void fill_path_slowdowns(std::vector<PagedBenchRow>& rows) {
    const PagedBenchRow* full = nullptr;
    for (const PagedBenchRow& r : rows)
        if (r.workload == "path" && r.budget >= 1.0) full = &r;
    if (!full || full->warm.ms <= 0.0) return;
    const double reference_ms = full->warm.ms;
    for (PagedBenchRow& r : rows)
        if (r.workload == "path") r.slowdown = r.warm.ms / reference_ms;
}

// ---- The file --------------------------------------------------------------

void check_config(const PagedBenchConfig& config) {
    if (config.budgets.empty()) throw Error("paged bench: no cache budgets");
    for (double f : config.budgets)
        if (!(f > 0.0 && f <= 1.0)) throw Error("paged bench: cache budget " + format("%g", f) + " is not in (0, 1]");
    if (config.passes < 2) throw Error("paged bench: --passes must be at least 2 (the first pass is the cold one)");
    if (config.repetitions < 1) throw Error("paged bench: --reps must be at least 1");
    if (config.width < 1 || config.height < 1) throw Error("paged bench: empty image");
}

// The converter's quads per page (64 .. 4096), from the largest page: a
// quad is 24 bytes and its share of the page BVH about 4 more.
uint32_t infer_page_quads(size_t largest_page_bytes) {
    if (largest_page_bytes == 0) return 0;
    const double quads = double(largest_page_bytes) / 28.0;
    const double power = std::clamp(std::round(std::log2(quads)), 6.0, 12.0);
    return uint32_t(1) << int(power);
}

std::string light_label(const Light& light) {
    char text[160];
    if (light.type == LightType::Directional)
        std::snprintf(text, sizeof(text), "directional light, towards (%.3g, %.3g, %.3g)", -light.direction.x,
                      -light.direction.y, -light.direction.z);
    else
        std::snprintf(text, sizeof(text), "%s light at (%.4g, %.4g, %.4g)",
                      light.type == LightType::Point ? "point" : "spot", light.position.x, light.position.y,
                      light.position.z);
    return text;
}

}  // namespace

PagedFileResult run_paged_bench(const std::string& path, const PagedBenchConfig& config, std::ostream& log) {
    check_config(config);
    std::optional<tbb::global_control> thread_limit;
    if (config.threads > 0) thread_limit.emplace(tbb::global_control::max_allowed_parallelism, size_t(config.threads));
    PagedFileResult result;
    PagedFileSummary& summary = result.summary;
    const FileProbe probe = probe_file(path, config.threads);
    const std::vector<ManagerModel>& models = probe.models;
    summary.info = probe.info;
    summary.camera = probe.camera;
    const std::optional<Light> light = config.light ? config.light : probe.light;
    summary.light = light ? light_label(*light) : "";
    summary.geometry_slot_bytes = models[0].slot_bytes;
    summary.inferred_page_quads = infer_page_quads(summary.geometry_slot_bytes);
    summary.mean_page_quads =
        summary.info.geometry_pages ? double(summary.info.quads) / double(summary.info.geometry_pages) : 0.0;
    const std::vector<TracedSet> sets = make_ray_sets(path, summary.camera, light, config, summary, log);

    for (double f : config.budgets) {
        std::vector<PagedCacheFigures> figures;
        const std::unique_ptr<World> scene = open_at_fraction(path, models, f, config.threads, figures);
        summary.budgets.emplace_back(f, figures);
        for (const TracedSet& set : sets) {
            log << "paged bench: " << path << ": cache " << budget_label(f) << ": " << set.name << " ("
                << thousands(set.rays.size()) << " rays)\n";
            result.rows.push_back(run_ray_set(scene->paged_scene(), set, f, config));
        }
        log << "paged bench: " << path << ": cache " << budget_label(f) << ": path tracing, " << config.passes
            << " passes\n";
        result.rows.push_back(run_path_tracing(*scene, summary.camera, f, config));
    }
    fill_path_slowdowns(result.rows);
    return result;
}

// ---- Output ------------------------------------------------------------------

namespace {

double memory_gib() {
    std::ifstream meminfo("/proc/meminfo");
    std::string key;
    double kib = 0.0;
    while (meminfo >> key >> kib) {
        if (key == "MemTotal:") return kib / (1024.0 * 1024.0);
        meminfo.ignore(256, '\n');
    }
    return 0.0;
}

int threads_used(const PagedBenchConfig& config) {
    return config.threads > 0 ? config.threads : machine_info().cores;
}

std::string info_line(const PagedFileSummary& s) {
    const PagedSceneInfo& i = s.info;
    std::ostringstream line;
    line << "== " << i.path << ": " << thousands(i.triangles) << " unique triangles";
    if (i.instances > 0)
        line << " (+ " << thousands(i.instances) << " instances showing " << thousands(i.instanced_triangles) << " more)";
    line << " in " << thousands(i.quads) << " quads; "
         << thousands(i.geometry_pages) << " geometry pages (page quads ~" << s.inferred_page_quads << ": largest page "
         << format("%.1f KiB", double(s.geometry_slot_bytes) / 1024.0) << ", " << format("%.0f", s.mean_page_quads)
         << " quads per page on average), " << thousands(i.attribute_pages) << " attribute pages ("
         << format("%.0f KiB", double(i.attribute_page_bytes) / 1024.0) << ", "
         << to_string(i.attributes) << " attributes), " << thousands(i.texture_pages)
         << " texture tiles; stored " << thousands(i.meshopt_pages) << " meshopt, " << thousands(i.zstd_pages)
         << " zstd, " << thousands(i.raw_pages) << " raw; file " << megabytes(double(i.file_bytes)) << " ("
         << format("%.1f", i.bytes_per_triangle()) << " bytes a unique triangle, "
         << megabytes(double(i.decoded_bytes)) << " decoded; reads: " << i.page_reads << "), always resident "
         << megabytes(double(i.resident_bytes)) << "; ";
    if (i.top_level == PagedTopLevel::Grid)
        line << "top grid " << i.grid[0] << "x" << i.grid[1] << "x" << i.grid[2] << "\n";
    else
        line << "top BVH of " << thousands(i.top_nodes) << " wide nodes\n";
    return line.str();
}

std::string budget_line(double f, const std::vector<PagedCacheFigures>& managers) {
    std::ostringstream line;
    line << "  " << pad(budget_label(f), 6, true);
    size_t total = 0;
    for (const PagedCacheFigures& m : managers) {
        if (m.pages == 0) continue;
        line << "  " << m.name << " " << thousands(m.slots) << "/" << thousands(m.pages) << " ("
             << megabytes(double(m.budget_bytes)) << ")";
        if (m.clamped) line << " [clamped: at least " << (m.name == "textures" ? "16 tiles" : "1 slot") << "]";
        total += m.budget_bytes;
    }
    line << "; total " << megabytes(double(total)) << "\n";
    return line.str();
}

// "97.3%", or "-" for a manager that was not asked.
std::string hit_rate(const PagedRunFigures& run, const std::string& name) {
    for (const PagedCacheFigures& c : run.caches)
        if (c.name == name && c.requests > 0) return format("%.1f%%", 100.0 * c.hit_rate());
    return "-";
}

void print_table_header(std::ostream& out) {
    out << pad("workload", 10, true) << pad("cache", 6, true) << pad("rays", 11) << pad("ms", 9) << pad("Mrays/s", 9)
        << pad("in-core", 9) << pad("slower", 8) << pad("cold ms", 9) << pad("cold Mr/s", 10) << pad("geo hit", 8)
        << pad("attr hit", 9) << pad("tex hit", 8) << pad("B/ray", 9) << pad("cold B/ray", 11) << pad("io ms", 8)
        << pad("trav ms", 9) << pad("iter", 8) << pad("hits", 9) << pad("agree", 9) << '\n';
}

void print_row(std::ostream& out, const PagedBenchRow& r) {
    const bool path = r.workload == "path";
    const double hit_diff = r.in_core_hits ? 100.0 * (double(r.paged_hits) - double(r.in_core_hits)) /
                                                 double(r.in_core_hits)
                                           : 0.0;
    out << pad(r.workload, 10, true) << pad(budget_label(r.budget), 6, true) << pad(thousands(r.rays), 11)
        << pad(format("%.1f", r.warm.ms), 9) << pad(format("%.2f", r.warm.mrays_per_s), 9)
        << pad(path ? "-" : format("%.2f", r.in_core_mrays_per_s), 9)
        << pad(r.slowdown > 0.0 ? format("%.2fx", r.slowdown) : "-", 8) << pad(format("%.1f", r.cold.ms), 9)
        << pad(format("%.2f", r.cold.mrays_per_s), 10) << pad(hit_rate(r.warm, "geometry"), 8)
        << pad(hit_rate(r.warm, "attributes"), 9) << pad(hit_rate(r.warm, "textures"), 8)
        << pad(format("%.1f", r.warm.bytes_per_ray), 9) << pad(format("%.1f", r.cold.bytes_per_ray), 11)
        << pad(format("%.1f", r.warm.io_ms), 8) << pad(format("%.1f", r.warm.traversal_ms), 9)
        << pad(format("%.1f", r.warm.iterations_per_loop), 8)
        << pad(path ? "-" : format("%+.2f%%", hit_diff), 9)
        << pad(path ? "-" : format("%.3f%%", 100.0 * r.agreement), 9) << '\n';
}

}  // namespace

void print_paged_header(std::ostream& out, const PagedBenchConfig& config, const std::string& command) {
    const MachineInfo machine = machine_info();
    out << "machine: " << machine.cpu << ", " << machine.cores << " hardware threads, "
        << format("%.1f GiB", memory_gib()) << "; " << iso_date_utc() << "; rayforge " << RAYFORGE_VERSION << '\n';
    out << "command: " << command << '\n';
    out << "paged bench: " << config.width << "x" << config.height << ", " << threads_used(config)
        << " threads; cache budgets";
    for (double f : config.budgets) out << ' ' << budget_label(f);
    out << " of the scene\n";
}

void print_paged_tables(std::ostream& out, const PagedFileResult& result, const PagedBenchConfig& config) {
    const PagedFileSummary& s = result.summary;
    out << '\n' << info_line(s);
    const std::string no_light = "none (no light in the file: give --light-dir)";
    out << "camera " << to_string(s.camera) << "; shadow set: " << (s.light.empty() ? no_light : s.light)
        << "\nin core: bvh/binned/bvh8 over the decoded pages (" << thousands(s.in_core_triangles)
        << " triangles, built in " << format("%.0f", s.in_core_build_ms) << " ms)\n";
    out << "ray sets: medians of " << config.repetitions << " traces after the cold one and a warm-up; path: "
        << config.max_depth << " bounces, median of passes 2.." << config.passes << ", the first pass cold\n";
    out << "caches (slots/pages and budget per manager):\n";
    for (const auto& [f, managers] : s.budgets) out << budget_line(f, managers);
    out << '\n';
    print_table_header(out);
    for (const PagedBenchRow& r : result.rows) print_row(out, r);
    out << "ms, Mrays/s: warm, the median run (path: the median pass, and all rays over the time of passes 2.."
        << config.passes << "); cold: the first run from empty caches (path: the first pass)\n"
           "slower: in-core Mrays/s / paged (ray sets), ms per pass / the f = 1 run's (path); hit: each manager's hit "
           "rate, warm\n"
           "B/ray: bytes read per ray, warm and cold; io, trav ms: reading pages and traversing, the mean per warm "
           "run (path: per pass); iter: query-loop iterations per batch (path: per pass)\n"
           "hits: paged - in-core closest hits (shadow: occluded rays); agree: rays with the same answer and primitive "
           "as in core\n";
    out.flush();
}

namespace {

Json run_json(const PagedRunFigures& r) {
    Json caches = Json::array();
    for (const PagedCacheFigures& c : r.caches)
        caches.push_back({{"name", c.name}, {"pages", c.pages}, {"slots", c.slots}, {"budget_bytes", c.budget_bytes},
                          {"requests", c.requests}, {"hits", c.hits}, {"hit_rate", c.hit_rate()},
                          {"pages_read", c.pages_read}, {"bytes_read", c.bytes_read}, {"evictions", c.evictions},
                          {"io_ms", c.io_ms}, {"manage_ms", c.manage_ms}});
    return {{"runs", r.runs}, {"ms", r.ms}, {"mean_ms", r.mean_ms}, {"mrays_per_s", r.mrays_per_s}, {"bytes_per_ray", r.bytes_per_ray},
            {"io_ms", r.io_ms}, {"manage_ms", r.manage_ms}, {"traversal_ms", r.traversal_ms}, {"sort_ms", r.sort_ms},
            {"iterations_per_loop", r.iterations_per_loop}, {"iterations_per_ray", r.iterations_per_ray},
            {"caches", caches}};
}

Json summary_json(const PagedFileSummary& s) {
    const PagedSceneInfo& i = s.info;
    Json budgets = Json::array();
    for (const auto& [f, managers] : s.budgets) {
        Json list = Json::array();
        for (const PagedCacheFigures& m : managers)
            list.push_back({{"name", m.name}, {"pages", m.pages}, {"slots", m.slots},
                            {"budget_bytes", m.budget_bytes}, {"clamped", m.clamped}});
        budgets.push_back({{"budget", f}, {"managers", list}});
    }
    return {{"path", i.path}, {"triangles", i.triangles}, {"quads", i.quads}, {"file_bytes", i.file_bytes},
            {"bytes_per_triangle", i.bytes_per_triangle()},
            {"geometry_pages", i.geometry_pages}, {"attribute_pages", i.attribute_pages},
            {"texture_pages", i.texture_pages}, {"grid", {i.grid[0], i.grid[1], i.grid[2]}},
            {"resident_bytes", i.resident_bytes}, {"attributes", to_string(i.attributes)},
            {"decoded_bytes", i.decoded_bytes}, {"page_reads", i.page_reads},
            {"pages_by_codec", {{"meshopt", i.meshopt_pages}, {"zstd", i.zstd_pages}, {"raw", i.raw_pages}}},
            {"attribute_page_bytes", i.attribute_page_bytes}, {"inferred_page_quads", s.inferred_page_quads},
            {"mean_page_quads", s.mean_page_quads}, {"largest_geometry_page_bytes", s.geometry_slot_bytes},
            {"camera", to_string(s.camera)}, {"shadow_light", s.light.empty() ? Json(nullptr) : Json(s.light)},
            {"in_core_triangles", s.in_core_triangles}, {"in_core_build_ms", s.in_core_build_ms},
            {"budgets", budgets}};
}

}  // namespace

void write_paged_json(const std::string& path, const std::vector<PagedFileResult>& results,
                      const PagedBenchConfig& config, const std::string& command) {
    const MachineInfo machine = machine_info();
    Json root;
    root["tool"] = "rayforge bench --paged";
    root["rayforge_version"] = RAYFORGE_VERSION;
    root["date"] = iso_date_utc();
    root["command"] = command;
    root["machine"] = {{"cpu", machine.cpu}, {"cores", machine.cores}, {"memory_gib", memory_gib()}};
    root["threads"] = threads_used(config);
    root["width"] = config.width;
    root["height"] = config.height;
    root["repetitions"] = config.repetitions;
    root["passes"] = config.passes;
    root["max_depth"] = config.max_depth;
    root["files"] = Json::array();
    root["records"] = Json::array();
    for (const PagedFileResult& result : results) {
        root["files"].push_back(summary_json(result.summary));
        for (const PagedBenchRow& r : result.rows)
            root["records"].push_back(
                {{"file", r.file}, {"budget", r.budget}, {"workload", r.workload}, {"rays", r.rays},
                 {"warm", run_json(r.warm)}, {"cold", run_json(r.cold)},
                 {"in_core_mrays_per_s", r.workload == "path" ? Json(nullptr) : Json(r.in_core_mrays_per_s)},
                 {"slowdown", r.slowdown > 0.0 ? Json(r.slowdown) : Json(nullptr)},
                 {"paged_hits", r.paged_hits}, {"in_core_hits", r.in_core_hits}, {"agreement", r.agreement},
                 {"first_pass_ms", r.workload == "path" ? Json(r.first_pass_ms) : Json(nullptr)}});
    }
    std::ofstream out(path);
    if (!out) throw Error(path + ": cannot write the JSON records");
    out << root.dump(2) << '\n';
    if (!out) throw Error(path + ": cannot write the JSON records");
}

}  // namespace rf::bench
