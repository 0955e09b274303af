// The CPU's rf::Renderer: each pass adds one sample to every pixel, either
// over 16x16 tiles rendered in parallel by TBB (every integrator; the path
// tracer as a megakernel, path by path) or, for the path tracer with
// options.wavefront, as a wavefront over chunks of kWavefrontChunkPaths
// paths (render/wavefront.h; the same image). Every sample draws its random
// numbers from its own counter-based stream keyed by (pixel, pass, seed),
// and each pixel's sum is added to in pass order, so an image does not
// depend on the thread count or on which thread renders which tile.
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <mutex>

#include "backend/backends.h"
#include "backend/cpu/accel_tracer.h"
#include "backend/cpu/cpu_wavefront.h"
#include "backend/cpu/host_display_image.h"
#include "backend/cpu/parallel.h"
#include "core/assert.h"
#include "rayforge/core/error.h"
#include "render/counting_tracer.h"
#include "render/pixel_sample.h"
#include "render/renderer_base.h"
#include "render/wavefront.h"

namespace rf {

void sort_queue_by_key(std::span<uint32_t> queue, std::span<uint32_t> keys) {
    RF_ASSERT(queue.size() == keys.size(), "a queue sorted by keys of another length");
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

namespace cpu {
namespace {

using Clock = std::chrono::steady_clock;
using Tracer = CountingTracer<AccelTracer, uint64_t>;

constexpr int kTileSize = 16;
constexpr size_t kStageGrain = 256;  // paths per task in the per-path stages

// Query counts of one pass, added to from many tasks.
struct RayTally {
    std::atomic<uint64_t> closest{0}, shadow{0};
};

// body(tracer, i) for i in [0, n) in parallel, with a counting tracer per task.
template <class Body>
void for_each_counted(const Accel& accel, size_t n, RayTally& tally, Body&& body) {
    parallel::for_range(size_t(0), n, kStageGrain, [&](size_t lo, size_t hi) {
        uint64_t closest = 0, shadow = 0;
        const AccelTracer inner{&accel, nullptr};
        const Tracer tracer{inner, &closest, &shadow};
        for (size_t i = lo; i < hi; ++i) body(tracer, uint32_t(i));
        tally.closest += closest;
        tally.shadow += shadow;
    });
}

// The CPU side of run_wavefront: one chunk's queues in host vectors, each
// stage a parallel loop over its items (compaction serial, in queue order).
class CpuWavefront {
public:
    CpuWavefront(const Accel& accel, const SceneView& view, const IntegratorSettings& settings, uint32_t sample,
                 const Films& films, size_t capacity)
        : accel_(accel), view_(view), settings_(settings), sample_(sample), films_(films) {
        paths_.resize(capacity);
        if (settings.aovs) aovs_.resize(capacity);
        for (auto* v : {&active_, &next_active_, &keys_, &shadow_slots_}) v->resize(capacity);
        rays_.resize(capacity);
        hits_.resize(capacity);
        found_.resize(capacity);
        shadows_.resize(capacity);
        for (auto* v : {&has_shadow_, &goes_on_, &blocked_}) v->resize(capacity);
    }

    void start_chunk(uint32_t first_pixel) { first_pixel_ = first_pixel; }

    void generate(uint32_t count) {
        const WavefrontQueues q = queues();
        parallel::for_range(0u, count, uint32_t(kStageGrain), [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i < hi; ++i) wavefront_generate(settings_, sample_, first_pixel_, q, i);
        });
    }
    void sort(uint32_t active) {
        const Clock::time_point start = Clock::now();
        const WavefrontQueues q = queues();
        parallel::for_range(0u, active, uint32_t(kStageGrain), [&](uint32_t lo, uint32_t hi) {
            for (uint32_t k = lo; k < hi; ++k) wavefront_sort_key(settings_, q, k);
        });
        sort_queue_by_key(std::span<uint32_t>(active_.data(), active), std::span<uint32_t>(keys_.data(), active));
        sort_ms += std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    }
    // First hits in one batch query, then each path past its cut-outs.
    void extend(uint32_t active) {
        for (uint32_t k = 0; k < active; ++k) rays_[k] = paths_[active_[k]].ray;
        accel_.intersect(std::span<const Ray>(rays_.data(), active), std::span<Hit>(hits_.data(), active));
        tally.closest += active;
        const WavefrontQueues q = queues();
        for_each_counted(accel_, active, tally, [&](const Tracer& tracer, uint32_t k) {
            wavefront_complete_extension(tracer, view_, q, k, hits_[k]);
        });
    }
    void shade(uint32_t active) {
        const WavefrontQueues q = queues();
        parallel::for_range(0u, active, uint32_t(kStageGrain), [&](uint32_t lo, uint32_t hi) {
            for (uint32_t k = lo; k < hi; ++k) wavefront_shade(view_, settings_.path, q, k);
        });
    }
    WaveSizes compact(uint32_t active) {
        WaveSizes sizes;
        for (uint32_t k = 0; k < active; ++k) {
            if (goes_on_[k]) next_active_[sizes.active++] = active_[k];
            if (has_shadow_[k]) shadow_slots_[sizes.shadows++] = k;
        }
        return sizes;
    }
    // Opaque scenes answer with one batch any-hit query; with cut-outs or
    // blended surfaces each shadow ray walks from hit to hit.
    void connect(uint32_t shadows) {
        const WavefrontQueues q = queues();
        if (view_.has_transparent_materials()) {
            for_each_counted(accel_, shadows, tally, [&](const Tracer& tracer, uint32_t j) {
                wavefront_connect(tracer, view_, q, j);
            });
            return;
        }
        for (uint32_t j = 0; j < shadows; ++j) rays_[j] = wavefront_shadow_ray(q, j);
        accel_.occluded(std::span<const Ray>(rays_.data(), shadows), std::span<uint8_t>(blocked_.data(), shadows));
        tally.shadow += shadows;
        parallel::for_range(0u, shadows, uint32_t(kStageGrain), [&](uint32_t lo, uint32_t hi) {
            for (uint32_t j = lo; j < hi; ++j) {
                const ShadowConnection& s = shadows_[shadow_slots_[j]];
                if (!blocked_[j]) paths_[s.path].radiance += s.contribution;
            }
        });
    }
    void swap_queues() { std::swap(active_, next_active_); }
    void accumulate(uint32_t count) {
        const WavefrontQueues q = queues();
        parallel::for_range(0u, count, uint32_t(kStageGrain), [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i < hi; ++i) wavefront_accumulate(q, i, settings_.clamp, films_);
        });
    }

    RayTally tally;
    double sort_ms = 0.0;

private:
    [[nodiscard]] WavefrontQueues queues() {
        return {paths_.data(),   aovs_.empty() ? nullptr : aovs_.data(),
                active_.data(),  next_active_.data(),
                keys_.data(),    found_.data(),
                shadows_.data(), has_shadow_.data(),
                goes_on_.data(), shadow_slots_.data()};
    }

    const Accel& accel_;
    const SceneView& view_;
    const IntegratorSettings& settings_;
    uint32_t sample_;
    Films films_;
    uint32_t first_pixel_ = 0;
    std::vector<PathState> paths_;
    std::vector<FirstHitAovs> aovs_;
    std::vector<uint32_t> active_, next_active_, keys_, shadow_slots_;
    std::vector<Ray> rays_;
    std::vector<Hit> hits_;
    std::vector<PathHit> found_;
    std::vector<ShadowConnection> shadows_;
    std::vector<uint8_t> has_shadow_, goes_on_, blocked_;
};

class CpuRenderer final : public RendererBase {
public:
    CpuRenderer(const Scene& scene, const SceneGeometry& geometry, const Accel& accel, const Camera& camera,
                const RenderOptions& options)
        : RendererBase(scene, geometry, accel, camera, options) {
        reset();
    }

    void render_pass_recorded(std::vector<TracedRay>& rays) override {
        rays.clear();
        run_recorded_pass(rays);
    }

    [[nodiscard]] std::unique_ptr<DisplayImage> make_display_image() const override {
        return std::make_unique<HostDisplayImage>();
    }

    void update_display(DisplayImage& display, const ToneMapping& tone) const override {
        auto* host = dynamic_cast<HostDisplayImage*>(&display);
        if (!host) throw Error("update_display: the display image is not a CPU one (make it with this renderer)");
        const float scale = passes() > 0 ? 1.0f / float(passes()) : 0.0f;  // image()'s scale
        parallel::with_threads(options().threads,
                               [&] { host->assign(color_, scale, options().width, options().height, tone); });
    }

private:
    bool run_pass(const ProgressCallback& progress, std::vector<TracedRay>* log, const std::atomic<bool>* cancel,
                  PassStats& stats) override {
        const RenderOptions& o = options();
        // A recorded pass is traced path by path, so its log keeps tile order
        // (the wavefront renders the same image).
        return parallel::with_threads(o.threads, [&] {
            if (o.integrator == IntegratorKind::Path && o.wavefront && !log)
                return wavefront_pass(progress, cancel, stats);
            return tile_pass(progress, log, cancel, stats);
        });
    }

    bool tile_pass(const ProgressCallback& progress, std::vector<TracedRay>* log, const std::atomic<bool>* cancel,
                   PassStats& stats);
    bool wavefront_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel, PassStats& stats);

    [[nodiscard]] Films films() {
        if (albedo_.empty()) return {color_.data(), nullptr, nullptr, nullptr};
        return {color_.data(), albedo_.data(), normal_.data(), depth_.data()};
    }

    [[nodiscard]] Image film_sums(Film film) const override {
        const std::vector<Vec3f>& sums = film == Film::Color    ? color_
                                         : film == Film::Albedo ? albedo_
                                         : film == Film::Normal ? normal_
                                                                : depth_;
        if (sums.empty()) return {};
        Image image(options().width, options().height);
        image.pixels = sums;
        return image;
    }

    void reset_films() override {
        const size_t pixels = size_t(options().width) * size_t(options().height);
        const auto film = [&](bool wanted) { return std::vector<Vec3f>(wanted ? pixels : 0, Vec3f(0.0f)); };
        color_ = film(true);
        albedo_ = film(options().aovs);
        normal_ = film(options().aovs);
        depth_ = film(options().aovs);
    }

    std::vector<Vec3f> color_, albedo_, normal_, depth_;
};

bool CpuRenderer::tile_pass(const ProgressCallback& progress, std::vector<TracedRay>* log,
                            const std::atomic<bool>* cancel, PassStats& stats) {
    const IntegratorSettings& s = settings();
    const int tiles_x = (s.width + kTileSize - 1) / kTileSize;
    const int tile_count = tiles_x * ((s.height + kTileSize - 1) / kTileSize);
    const uint32_t sample = uint32_t(passes());
    const Films out = films();
    std::vector<std::vector<TracedRay>> tile_logs(log ? size_t(tile_count) : 0);
    RayTally tally;
    int tiles_done = 0;
    std::mutex progress_mutex;

    std::atomic<bool> cancelled{false};
    const auto render_tile = [&](int tile) {
        if (cancel && cancel->load(std::memory_order_relaxed)) {
            cancelled.store(true, std::memory_order_relaxed);
            return;
        }
        uint64_t closest = 0, shadow = 0;
        const AccelTracer inner{&accel(), log ? &tile_logs[size_t(tile)] : nullptr};
        const Tracer tracer{inner, &closest, &shadow};
        const int x0 = (tile % tiles_x) * kTileSize, y0 = (tile / tiles_x) * kTileSize;
        const int x1 = std::min(x0 + kTileSize, s.width), y1 = std::min(y0 + kTileSize, s.height);
        for (int y = y0; y < y1; ++y)
            for (int x = x0; x < x1; ++x)
                add_pixel_sample<true>(tracer, tables().view(), s, sample, uint32_t(y * s.width + x), out);
        tally.closest += closest;
        tally.shadow += shadow;
        if (progress) {
            // Counting under the lock keeps the reported fractions increasing.
            std::lock_guard<std::mutex> lock(progress_mutex);
            progress(double(++tiles_done) / double(tile_count));
        }
    };
    parallel::for_each_index(0, tile_count, render_tile);
    stats.closest_rays = tally.closest.load();
    stats.shadow_rays = tally.shadow.load();
    if (log)
        for (const auto& tile : tile_logs) log->insert(log->end(), tile.begin(), tile.end());
    return !cancelled.load();
}

bool CpuRenderer::wavefront_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel,
                                 PassStats& stats) {
    const IntegratorSettings& s = settings();
    const uint32_t pixels = uint32_t(s.width) * uint32_t(s.height);
    CpuWavefront wavefront(accel(), tables().view(), s, uint32_t(passes()), films(),
                           std::min(pixels, kWavefrontChunkPaths));
    for (uint32_t first = 0; first < pixels; first += kWavefrontChunkPaths) {
        if (cancel && cancel->load(std::memory_order_relaxed)) return false;
        const uint32_t count = std::min(kWavefrontChunkPaths, pixels - first);
        wavefront.start_chunk(first);
        run_wavefront(wavefront, s, count, stats.waves);
        if (progress) progress(double(first + count) / double(pixels));
    }
    stats.closest_rays = wavefront.tally.closest.load();
    stats.shadow_rays = wavefront.tally.shadow.load();
    stats.sort_ms = wavefront.sort_ms;
    return true;
}

}  // namespace

std::unique_ptr<Renderer> make_renderer(const Scene& scene, const SceneGeometry& geometry, const Accel& accel,
                                        const Camera& camera, const RenderOptions& options) {
    return std::make_unique<CpuRenderer>(scene, geometry, accel, camera, options);
}

}  // namespace cpu
}  // namespace rf
