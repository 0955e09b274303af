// The CPU's wavefront path tracer (over render/wavefront.h): its chunk size,
// its queue sort, and the stage runner CpuWavefront, shared by the in-core
// renderer (backend/cpu/cpu_renderer.cpp) and the paged scenes' renderer
// (ooc/paged_renderer.cpp), which differ only in how batched queries are
// answered (WavefrontQueries).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <span>
#include <vector>

#include "backend/cpu/accel_tracer.h"
#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "render/counting_tracer.h"
#include "render/pixel_sample.h"
#include "render/wavefront.h"

namespace rf {

// Paths in flight at once: bounds the queues' memory (about 200 bytes a path).
inline constexpr uint32_t kWavefrontChunkPaths = 1u << 16;

// Stable sort of `queue` by `keys` (keys[i] belongs to queue[i]; both are
// permuted together): a least-significant-digit radix sort, 8 bits a round.
void sort_queue_by_key(std::span<uint32_t> queue, std::span<uint32_t> keys);

namespace cpu {

// How a CPU wavefront answers its batched queries.
class WavefrontQueries {
public:
    virtual ~WavefrontQueries() = default;
    // Closest hits; a hit's prim must be what the wavefront's view shades with.
    virtual void closest(std::span<const Ray> rays, std::span<Hit> hits) = 0;
    virtual void any(std::span<const Ray> rays, std::span<uint8_t> occluded) = 0;
};

// An Accel's own batches.
class AccelQueries final : public WavefrontQueries {
public:
    explicit AccelQueries(const Accel& accel) : accel_(accel) {}
    void closest(std::span<const Ray> rays, std::span<Hit> hits) override { accel_.intersect(rays, hits); }
    void any(std::span<const Ray> rays, std::span<uint8_t> occluded) override { accel_.occluded(rays, occluded); }

private:
    const Accel& accel_;
};

using CountedTracer = CountingTracer<AccelTracer, uint64_t>;

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
        const CountedTracer tracer{inner, &closest, &shadow};
        for (size_t i = lo; i < hi; ++i) body(tracer, uint32_t(i));
        tally.closest += closest;
        tally.shadow += shadow;
    });
}

// The CPU side of run_wavefront: one chunk's queues in host vectors, each
// stage a parallel loop over its items (compaction serial, in queue order).
template <class View>
class CpuWavefront {
public:
    // `queries` answers the batched extensions and shadow rays (an Accel's
    // batches, or a paged scene's query loops); `accel` the single queries
    // past cut-outs and blended surfaces.
    CpuWavefront(const Accel& accel, WavefrontQueries& queries, const View& view, const IntegratorSettings& settings,
                 uint32_t sample, const Films& films, size_t capacity)
        : accel_(accel), queries_(queries), view_(view), settings_(settings), sample_(sample), films_(films) {
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
        const auto start = std::chrono::steady_clock::now();
        const WavefrontQueues q = queues();
        parallel::for_range(0u, active, uint32_t(kStageGrain), [&](uint32_t lo, uint32_t hi) {
            for (uint32_t k = lo; k < hi; ++k) wavefront_sort_key(settings_, q, k);
        });
        sort_queue_by_key(std::span<uint32_t>(active_.data(), active), std::span<uint32_t>(keys_.data(), active));
        sort_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    }
    // First hits in one batch query, then each path past its cut-outs.
    void extend(uint32_t active) {
        for (uint32_t k = 0; k < active; ++k) rays_[k] = paths_[active_[k]].ray;
        queries_.closest(std::span<const Ray>(rays_.data(), active), std::span<Hit>(hits_.data(), active));
        tally.closest += active;
        const WavefrontQueues q = queues();
        for_each_counted(accel_, active, tally, [&](const CountedTracer& tracer, uint32_t k) {
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
            for_each_counted(accel_, shadows, tally, [&](const CountedTracer& tracer, uint32_t j) {
                wavefront_connect(tracer, view_, q, j);
            });
            return;
        }
        for (uint32_t j = 0; j < shadows; ++j) rays_[j] = wavefront_shadow_ray(q, j);
        queries_.any(std::span<const Ray>(rays_.data(), shadows), std::span<uint8_t>(blocked_.data(), shadows));
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
    WavefrontQueries& queries_;
    const View& view_;
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

}  // namespace cpu
}  // namespace rf
