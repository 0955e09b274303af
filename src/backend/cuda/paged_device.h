// Ray queries on a paged scene with the geometry cache in device memory
// (Garanzha 2014, ch. 6; backend/cuda/paged_device.cu): the dissertation's two
// levels, host memory -> device memory, with the host level a PageCache
// filled from the file (disk -> host memory, as on the CPU). Hits are
// PagedEngine's (same file, any budgets): the same paged_iteration runs per
// ray, only the schedule differs.
//
// Internal to the CUDA backend: include it from .cu files and the GPU tests
// only (a build without nvcc has no definition of it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "ooc/device_page_cache_steps.h"
#include "ooc/pack_file.h"
#include "ooc/page_cache.h"
#include "rayforge/math/ray.h"

namespace rf::cuda {

struct DevicePagedBudgets {
    // Device memory for geometry: a descriptor per page, one staging area
    // and the pool of slots (pack::device_slots_within_budget).
    size_t device_bytes = size_t(1) << 30;
    // The host level: a PageCache of the geometry pages (its own accounting).
    size_t host_bytes = size_t(1) << 30;
    // One staging fill (Garanzha 2014's 1 MB gather array): at least one page.
    size_t staging_bytes = size_t(pack::kDefaultStagingBytes);
};

// Counts since construction or the last reset_stats().
struct DevicePagedStats {
    pack::DeviceLoopStats loop;
    pack::DevicePoolStats device_pool;
    uint64_t runs = 0, cells = 0, middle = 0, pages = 0, nodes = 0, quads = 0;  // summed PagedCounters
    double iterate_ms = 0.0;  // kernels and compaction, to their end
    double manage_ms = 0.0;   // descriptor copies and the swap decision
    double staging_ms = 0.0;  // host cache, gather, copies and scatters
};

class DevicePagedEngine {
public:
    // Uploads the resident levels to cuda:`device` and sizes the device pool
    // and the host cache from the budgets; rf::Error when either holds no
    // page or the device is missing.
    DevicePagedEngine(std::shared_ptr<const pack::PackFile> file, const DevicePagedBudgets& budgets, int device = 0);
    ~DevicePagedEngine();
    DevicePagedEngine(const DevicePagedEngine&) = delete;
    DevicePagedEngine& operator=(const DevicePagedEngine&) = delete;

    // Closest hits (Hit::prim = page * kTrianglesPerPageSlot + 2 * quad + half) and any hits.
    void intersect(std::span<const Ray> rays, std::span<Hit> hits);
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded);

    [[nodiscard]] const pack::PackFile& file() const;
    [[nodiscard]] uint32_t device_slot_count() const;
    [[nodiscard]] uint32_t device_cached_count() const;
    // Descriptors, staging and pool: within budgets.device_bytes.
    [[nodiscard]] size_t device_cache_bytes() const;
    // The resident levels on the device, and the ray buffers at their largest so far.
    [[nodiscard]] size_t device_resident_bytes() const;
    [[nodiscard]] size_t device_ray_bytes_peak() const;
    // Host memory: the host cache, the planner's tables, two pinned staging areas.
    [[nodiscard]] size_t host_bytes() const;
    [[nodiscard]] const pack::PageCache& host_cache() const;
    // The device pool's descriptors as the host last saw them.
    [[nodiscard]] std::span<const uint32_t> device_descriptors() const;
    [[nodiscard]] const DevicePagedStats& stats() const;
    void reset_stats();
    // Both levels emptied (a cold start).
    void clear_caches();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace rf::cuda
