// The CPU renderer of paged worlds (cpu::make_paged_renderer): the in-core
// renderer's integrators over a view whose shading records and textures
// come through the page managers (Garanzha 2014, §6.4-6.5).
//
// Queries must be batched so that the query loop can suspend rays on
// missing pages and load what a whole batch asked for (§6.3.3):
//   - the path tracer runs as the CPU wavefront (render/wavefront.h), whose
//     extensions and shadow rays are batches; a batch's closest hits get
//     their shading records from the attribute manager into a table by
//     slot, and each hit's prim becomes its slot, which the view shades;
//   - Whitted, AO and normals run per pixel by replay: each round, every
//     unfinished pixel runs its sample against the answers it has so far;
//     its first unanswered query is collected instead of traced, and the
//     sample is dropped; the round's queries are traced as two batches and
//     their answers appended. A pixel whose sample ran through is added to
//     the films. A sample's random numbers depend only on (pixel, pass,
//     seed), so a replay asks the same queries in the same order, and the
//     image is the one a direct render of the same answers gives.
// Textures are read on demand through the texture tile cache (§6.5,
// ooc/texture_cache.h). Materials are opaque (the converter says so).
#include <algorithm>
#include <atomic>
#include <vector>

#include "backend/backends.h"
#include "backend/cpu/cpu_wavefront.h"
#include "backend/cpu/host_film_renderer.h"
#include "core/assert.h"
#include "core/parallel.h"
#include "ooc/paged_scene_impl.h"
#include "rayforge/core/error.h"
#include "render/pixel_sample.h"

namespace rf {

namespace {

// The integrators' view of a paged scene: SceneView with shading records
// from the current batch's table and textures read through the tile cache.
struct PagedShadingView : SceneView {
    const PagedTexture* paged_textures = nullptr;
    uint32_t paged_texture_count = 0;
    [[nodiscard]] const PagedTexture* texture(int32_t id) const {
        return (id >= 0 && uint32_t(id) < paged_texture_count) ? &paged_textures[id] : nullptr;
    }
};

// Answers of one pixel's queries, in the order the sample asked them.
struct Answer {
    Hit hit;
    uint8_t occluded = 0;
};

// The tracer a replayed sample runs against (see the file's comment).
struct ReplayTracer {
    const std::vector<Answer>* answers = nullptr;
    mutable size_t next = 0;
    mutable bool blocked = false;
    mutable Ray pending;
    mutable bool pending_any = false;

    [[nodiscard]] Hit intersect(const Ray& ray) const {
        if (!blocked && next < answers->size()) return (*answers)[next++].hit;
        ask(ray, false);
        return Hit{};
    }
    [[nodiscard]] bool occluded(const Ray& ray) const {
        if (!blocked && next < answers->size()) return (*answers)[next++].occluded != 0;
        ask(ray, true);
        return true;
    }
    void ask(const Ray& ray, bool any) const {
        if (blocked) return;
        blocked = true;
        pending = ray;
        pending_any = any;
    }
};

// The world's scene is the file's shell (world/world.cpp): lights,
// environment and a bounds-only geometry (no triangles, so no emitters:
// paged emissive surfaces shine when hit but are not sampled as lights).
class PagedRenderer final : public cpu::HostFilmRenderer {
public:
    PagedRenderer(std::shared_ptr<WorldCore> world, pack::PagedSceneImpl& paged, const Camera& camera,
                  const RenderOptions& options)
        : HostFilmRenderer(std::move(world), camera, options), paged_(paged) {
        start();
    }

    void render_pass_recorded(std::vector<TracedRay>&) override {
        throw Error("recorded passes are not available for paged scenes");
    }

private:
    void tables_changed() override {
        static_cast<SceneView&>(view_) = tables().view();
        const pack::PackFile& file = paged_.file();
        view_.materials = file.materials().data();
        view_.material_count = uint32_t(file.materials().size());
        view_.transparent_materials = false;
        view_.paged_textures = paged_.textures().data();
        view_.paged_texture_count = uint32_t(paged_.textures().size());
    }

    bool run_pass(const ProgressCallback& progress, std::vector<TracedRay>*, const std::atomic<bool>* cancel,
                  PassStats& stats) override {
        return parallel::with_threads(options().threads, [&] {
            return options().integrator == IntegratorKind::Path ? wavefront_pass(progress, cancel, stats)
                                                                : replay_pass(progress, cancel, stats);
        });
    }

    bool wavefront_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel, PassStats& stats);
    bool replay_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel, PassStats& stats);
    // False when `cancel` was seen set between rounds.
    bool replay_chunk(uint32_t first, uint32_t count, const std::atomic<bool>* cancel, PassStats& stats);
    // Closest hits of `rays` with their shading records appended to records_; each found hit's prim becomes its record.
    void trace_and_shade(std::span<const Ray> rays, std::span<Hit> hits);

    // Paths (or pixels) per batch: large batches amortise page loads (§6.6: up to 16M rays).
    [[nodiscard]] uint32_t chunk() const { return paged_.batch_paths(); }

    pack::PagedSceneImpl& paged_;
    PagedShadingView view_;
    std::vector<ShadingTriangle> records_;
    std::vector<uint32_t> instances_;  // of the last batch's hits
};

void PagedRenderer::trace_and_shade(std::span<const Ray> rays, std::span<Hit> hits) {
    instances_.resize(hits.size());
    paged_.engine().intersect(rays, hits, instances_);
    const size_t base = records_.size();
    records_.resize(base + hits.size());
    paged_.engine().fetch_shading(hits, std::span<ShadingTriangle>(records_.data() + base, hits.size()), instances_);
    for (size_t k = 0; k < hits.size(); ++k)
        if (hits[k].found()) hits[k].prim = uint32_t(base + k);
    view_.shading_triangles = records_.data();
}

// The wavefront's batches through the engine; a batch's records replace the last batch's.
class PagedQueries final : public cpu::WavefrontQueries {
public:
    explicit PagedQueries(std::function<void(std::span<const Ray>, std::span<Hit>)> closest,
                          pack::PagedEngine& engine)
        : closest_(std::move(closest)), engine_(engine) {}
    void closest(std::span<const Ray> rays, std::span<Hit> hits) override { closest_(rays, hits); }
    void any(std::span<const Ray> rays, std::span<uint8_t> occluded) override { engine_.occluded(rays, occluded); }

private:
    std::function<void(std::span<const Ray>, std::span<Hit>)> closest_;
    pack::PagedEngine& engine_;
};

bool PagedRenderer::wavefront_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel,
                                   PassStats& stats) {
    const IntegratorSettings& s = settings();
    const uint32_t pixels = uint32_t(s.width) * uint32_t(s.height);
    PagedQueries queries(
        [&](std::span<const Ray> rays, std::span<Hit> hits) {
            records_.clear();
            trace_and_shade(rays, hits);
        },
        paged_.engine());
    cpu::CpuWavefront<PagedShadingView> wavefront(accel(), queries, view_, s, uint32_t(passes()), films(),
                                                  std::min(pixels, chunk()));
    for (uint32_t first = 0; first < pixels; first += chunk()) {
        if (cancel && cancel->load(std::memory_order_relaxed)) return false;
        const uint32_t count = std::min(chunk(), pixels - first);
        wavefront.start_chunk(first);
        run_wavefront(wavefront, s, count, stats.waves);
        if (progress) progress(double(first + count) / double(pixels));
    }
    stats.closest_rays = wavefront.tally.closest.load();
    stats.shadow_rays = wavefront.tally.shadow.load();
    stats.sort_ms = wavefront.sort_ms;
    return true;
}

bool PagedRenderer::replay_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel, PassStats& stats) {
    const uint32_t pixels = uint32_t(settings().width) * uint32_t(settings().height);
    for (uint32_t first = 0; first < pixels; first += chunk()) {
        if (cancel && cancel->load(std::memory_order_relaxed)) return false;
        const uint32_t count = std::min(chunk(), pixels - first);
        if (!replay_chunk(first, count, cancel, stats)) return false;
        if (progress) progress(double(first + count) / double(pixels));
    }
    return true;
}

bool PagedRenderer::replay_chunk(uint32_t first, uint32_t count, const std::atomic<bool>* cancel, PassStats& stats) {
    const IntegratorSettings& s = settings();
    const uint32_t sample = uint32_t(passes());
    const Films out = films();
    std::vector<std::vector<Answer>> answers(count);
    std::vector<uint32_t> open(count);  // pixels (chunk-relative) still replaying
    for (uint32_t k = 0; k < count; ++k) open[k] = k;
    std::vector<Ray> asked(count);
    std::vector<uint8_t> asked_any(count), blocked(count);
    std::vector<Ray> rays;
    std::vector<Hit> hits;
    std::vector<uint8_t> occluded;
    std::vector<uint32_t> closest_of, any_of;
    records_.clear();
    while (!open.empty()) {
        if (cancel && cancel->load(std::memory_order_relaxed)) return false;
        view_.shading_triangles = records_.data();
        parallel::for_range(size_t(0), open.size(), size_t(64), [&](size_t lo, size_t hi) {
            for (size_t j = lo; j < hi; ++j) {
                const uint32_t k = open[j];
                ReplayTracer tracer;
                tracer.answers = &answers[k];
                const PixelSample p = sample_pixel<true>(tracer, view_, s, sample, first + k);
                blocked[j] = tracer.blocked ? 1 : 0;
                if (!tracer.blocked) {
                    add_to_films(p, s, first + k, out);
                    continue;
                }
                asked[j] = tracer.pending;
                asked_any[j] = tracer.pending_any ? 1 : 0;
            }
        });
        // The round's queries, closest and any hit, each one batch.
        closest_of.clear();
        any_of.clear();
        for (size_t j = 0; j < open.size(); ++j)
            if (blocked[j]) (asked_any[j] ? any_of : closest_of).push_back(uint32_t(j));
        rays.resize(closest_of.size());
        hits.resize(closest_of.size());
        for (size_t i = 0; i < closest_of.size(); ++i) rays[i] = asked[closest_of[i]];
        trace_and_shade(rays, hits);
        for (size_t i = 0; i < closest_of.size(); ++i) answers[open[closest_of[i]]].push_back({hits[i], 0});
        rays.resize(any_of.size());
        occluded.resize(any_of.size());
        for (size_t i = 0; i < any_of.size(); ++i) rays[i] = asked[any_of[i]];
        paged_.engine().occluded(rays, occluded);
        for (size_t i = 0; i < any_of.size(); ++i) answers[open[any_of[i]]].push_back({Hit{}, occluded[i]});
        stats.closest_rays += closest_of.size();
        stats.shadow_rays += any_of.size();
        size_t kept = 0;
        for (size_t j = 0; j < open.size(); ++j)
            if (blocked[j]) open[kept++] = open[j];
        open.resize(kept);
    }
    return true;
}

}  // namespace

std::unique_ptr<Renderer> cpu::make_paged_renderer(std::shared_ptr<WorldCore> world, const Camera& camera,
                                                   const RenderOptions& options) {
    auto* paged = dynamic_cast<pack::PagedSceneImpl*>(world->paged.get());
    RF_ASSERT(paged, "a paged world not opened by open_paged_scene");
    return std::make_unique<PagedRenderer>(std::move(world), *paged, camera, options);
}

}  // namespace rf
