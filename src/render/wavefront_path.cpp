// The CPU wavefront driver (see wavefront_path.h): the path_stages.h stages
// run queue by queue over chunks of kWavefrontChunkPaths paths.

#include "render/wavefront_path.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>

#include "backend/cpu/parallel.h"
#include "render/ray_sort_key.h"

namespace rf {

WavefrontStats& WavefrontStats::operator+=(const WavefrontStats& o) {
    if (waves.size() < o.waves.size()) waves.resize(o.waves.size());
    for (size_t i = 0; i < o.waves.size(); ++i) {
        waves[i].paths += o.waves[i].paths;
        waves[i].shadow_rays += o.waves[i].shadow_rays;
    }
    closest_rays += o.closest_rays;
    shadow_rays += o.shadow_rays;
    sort_seconds += o.sort_seconds;
    return *this;
}

void sort_queue_by_key(std::span<uint32_t> queue, std::span<uint32_t> keys) {
    const size_t n = std::min(queue.size(), keys.size());
    if (n < 2) return;
    std::vector<uint32_t> other_queue(n), other_keys(n);
    uint32_t *from_q = queue.data(), *from_k = keys.data();
    uint32_t *to_q = other_queue.data(), *to_k = other_keys.data();
    for (int shift = 0; shift < 32; shift += 8) {
        std::array<size_t, 257> start{};
        for (size_t i = 0; i < n; ++i) ++start[((from_k[i] >> shift) & 0xffu) + 1];
        // A digit every key shares moves nothing: skip the scatter.
        if (std::any_of(start.begin() + 1, start.end(), [&](size_t c) { return c == n; })) continue;
        for (size_t d = 1; d < start.size(); ++d) start[d] += start[d - 1];
        for (size_t i = 0; i < n; ++i) {
            const size_t to = start[(from_k[i] >> shift) & 0xffu]++;
            to_q[to] = from_q[i];
            to_k[to] = from_k[i];
        }
        std::swap(from_q, to_q);
        std::swap(from_k, to_k);
    }
    if (from_q != queue.data()) {
        std::copy(from_q, from_q + n, queue.data());
        std::copy(from_k, from_k + n, keys.data());
    }
}

namespace {

using Clock = std::chrono::steady_clock;

constexpr size_t kStageGrain = 256;  // paths per task in the per-path stages

// Everything one chunk of paths keeps between stages; reused chunk to chunk.
// Arrays indexed by path hold the paths; those indexed by slot follow the
// order of the active queue of the current round.
struct WavefrontQueues {
    std::vector<PathState> paths;
    std::vector<FirstHitAovs> aovs;          // by path, when wanted
    std::vector<uint32_t> active, next_active;  // path indices
    std::vector<uint32_t> keys;              // by slot, when sorting
    std::vector<Ray> rays;                   // by slot
    std::vector<Hit> hits;                   // by slot
    std::vector<PathHit> found;              // by slot
    std::vector<ShadowConnection> shadows;   // by slot
    std::vector<uint8_t> has_shadow, goes_on;  // by slot
    std::vector<uint32_t> shadow_slots;      // the slots that made a shadow connection, in order
    std::vector<Ray> shadow_rays;            // by shadow
    std::vector<uint8_t> blocked;            // by shadow

    void reserve(size_t n, bool aovs_wanted) {
        paths.resize(n);
        if (aovs_wanted) aovs.resize(n);
        for (auto* v : {&active, &next_active, &keys, &shadow_slots}) v->resize(n);
        for (auto* v : {&rays, &shadow_rays}) v->resize(n);
        hits.resize(n);
        found.resize(n);
        shadows.resize(n);
        for (auto* v : {&has_shadow, &goes_on, &blocked}) v->resize(n);
    }
};

// body(i) for i in [0, n) in parallel, with a tracer whose query counts are
// added to `closest` and `shadow`.
template <class Body>
void for_each_path(const WavefrontPass& pass, size_t n, std::atomic<uint64_t>& closest,
                   std::atomic<uint64_t>& shadow, Body&& body) {
    parallel::for_range(size_t(0), n, kStageGrain, [&](size_t lo, size_t hi) {
        uint64_t closest_here = 0, shadow_here = 0;
        const AccelTracer tracer{pass.accel, &closest_here, &shadow_here, nullptr};
        for (size_t i = lo; i < hi; ++i) body(tracer, i);
        closest += closest_here;
        shadow += shadow_here;
    });
}

void run_chunk(const WavefrontPass& pass, uint32_t first_pixel, uint32_t count, WavefrontQueues& q,
               const WavefrontFilms& films, WavefrontStats& stats) {
    const HostSceneView& view = *pass.view;
    const bool aovs_wanted = films.albedo != nullptr;
    std::atomic<uint64_t> closest{0}, shadow{0};

    // Generate.
    for_each_path(pass, count, closest, shadow, [&](const AccelTracer&, size_t i) {
        const uint32_t pixel = first_pixel + uint32_t(i);
        const int x = int(pixel % uint32_t(pass.width)), y = int(pixel / uint32_t(pass.width));
        q.paths[i] = generate_camera_path(pass.camera, x, y, pass.width, pass.height, pass.sample, pass.seed,
                                          pass.settings);
        if (aovs_wanted) q.aovs[i] = FirstHitAovs{};
        q.active[i] = uint32_t(i);
    });
    size_t active = count;

    for (size_t wave = 0; active > 0; ++wave) {
        if (stats.waves.size() <= wave) stats.waves.resize(wave + 1);
        stats.waves[wave].paths += active;
        const std::span<uint32_t> queue(q.active.data(), active);

        // Sort: neighbours in the queue start close and go the same way.
        if (pass.sort_rays && active > 1) {
            const Clock::time_point start = Clock::now();
            parallel::for_range(size_t(0), active, kStageGrain, [&](size_t lo, size_t hi) {
                for (size_t i = lo; i < hi; ++i) q.keys[i] = ray_sort_key(q.paths[queue[i]].ray, pass.sort_bounds);
            });
            sort_queue_by_key(queue, std::span<uint32_t>(q.keys.data(), active));
            stats.sort_seconds += std::chrono::duration<double>(Clock::now() - start).count();
        }

        // Extend: first hits in one batch, then each path past its cut-outs.
        for (size_t i = 0; i < active; ++i) q.rays[i] = q.paths[queue[i]].ray;
        pass.accel->intersect(std::span<const Ray>(q.rays.data(), active), std::span<Hit>(q.hits.data(), active));
        closest += active;
        for_each_path(pass, active, closest, shadow, [&](const AccelTracer& tracer, size_t i) {
            q.found[i] = complete_extension(tracer, view, q.paths[queue[i]], q.hits[i]);
        });

        // Shade.
        for_each_path(pass, active, closest, shadow, [&](const AccelTracer&, size_t i) {
            const uint32_t p = queue[i];
            bool has_shadow = false;
            q.goes_on[i] = shade_path(view, pass.settings, q.paths[p], q.found[i], aovs_wanted ? &q.aovs[p] : nullptr,
                                      q.shadows[i], has_shadow);
            q.shadows[i].path = p;
            q.has_shadow[i] = has_shadow;
        });
        size_t shadow_count = 0;
        for (size_t i = 0; i < active; ++i)
            if (q.has_shadow[i]) q.shadow_slots[shadow_count++] = uint32_t(i);
        stats.waves[wave].shadow_rays += shadow_count;

        // Connect: opaque scenes answer with one batch any-hit query; with
        // cut-outs or blended surfaces each ray walks from hit to hit.
        if (shadow_count > 0) {
            if (!view.has_transparent_materials()) {
                for (size_t j = 0; j < shadow_count; ++j) q.shadow_rays[j] = q.shadows[q.shadow_slots[j]].ray;
                pass.accel->occluded(std::span<const Ray>(q.shadow_rays.data(), shadow_count),
                                     std::span<uint8_t>(q.blocked.data(), shadow_count));
                shadow += shadow_count;
            } else {
                for_each_path(pass, shadow_count, closest, shadow, [&](const AccelTracer& tracer, size_t j) {
                    q.blocked[j] = connect_shadow(tracer, view, q.shadows[q.shadow_slots[j]]) ? 0 : 1;
                });
            }
            // Each path made at most one connection this round: no two tasks add to one path.
            parallel::for_range(size_t(0), shadow_count, kStageGrain, [&](size_t lo, size_t hi) {
                for (size_t j = lo; j < hi; ++j) {
                    if (q.blocked[j]) continue;
                    const ShadowConnection& s = q.shadows[q.shadow_slots[j]];
                    q.paths[s.path].radiance += s.contribution;
                }
            });
        }

        // Compact: the paths that go on, in queue order.
        size_t next = 0;
        for (size_t i = 0; i < active; ++i)
            if (q.goes_on[i]) q.next_active[next++] = queue[i];
        std::swap(q.active, q.next_active);
        active = next;
    }

    // Write the film where the progressive renderer does: one sample per pixel.
    parallel::for_range(size_t(0), size_t(count), kStageGrain, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const PathState& path = q.paths[i];
            films.color[path.pixel] += film_sample(path.radiance, pass.max_sample_value);
            if (!aovs_wanted) continue;
            films.albedo[path.pixel] += q.aovs[i].albedo;
            films.normal[path.pixel] += q.aovs[i].normal;
            films.depth[path.pixel] += Vec3f(q.aovs[i].depth);
        }
    });
    stats.closest_rays += closest.load();
    stats.shadow_rays += shadow.load();
}

}  // namespace

void render_wavefront_pass(const WavefrontPass& pass, const WavefrontFilms& films, WavefrontStats& stats) {
    const uint32_t pixels = uint32_t(pass.width) * uint32_t(pass.height);
    WavefrontQueues queues;
    queues.reserve(std::min(pixels, kWavefrontChunkPaths), films.albedo != nullptr);
    for (uint32_t first = 0; first < pixels; first += kWavefrontChunkPaths) {
        const uint32_t count = std::min(kWavefrontChunkPaths, pixels - first);
        run_chunk(pass, first, count, queues, films, stats);
        if (pass.progress) pass.progress(double(first + count) / double(pixels));
    }
}

}  // namespace rf
