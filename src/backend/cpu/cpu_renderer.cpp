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
#include "backend/cpu/host_film_renderer.h"
#include "core/parallel.h"
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

constexpr int kTileSize = 16;

class CpuRenderer final : public HostFilmRenderer {
public:
    CpuRenderer(std::shared_ptr<WorldCore> world, const Camera& camera, const RenderOptions& options)
        : HostFilmRenderer(std::move(world), camera, options) {
        start();
    }

    void render_pass_recorded(std::vector<TracedRay>& rays) override {
        rays.clear();
        run_recorded_pass(rays);
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
        const CountedTracer tracer{inner, &closest, &shadow};
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
    AccelQueries queries(accel());
    CpuWavefront<SceneView> wavefront(accel(), queries, tables().view(), s, uint32_t(passes()), films(),
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

std::unique_ptr<Renderer> make_renderer(std::shared_ptr<WorldCore> world, const Camera& camera,
                                        const RenderOptions& options) {
    return std::make_unique<CpuRenderer>(std::move(world), camera, options);
}

}  // namespace cpu
}  // namespace rf
