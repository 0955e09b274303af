// Out-of-core ray queries with the geometry cache in device memory: the
// dissertation's OOC-IRT data manager and query loop (Garanzha 2014, §6.2,
// Listing 6.1, Fig. 6.1, §6.3.3), with the host level a PageCache (disk ->
// host memory, as on the CPU) instead of the dissertation's whole scene in
// host memory.
//
// What runs where, per iteration of run_device_query_loop
// (ooc/device_page_cache_steps.h, the loop and steps the CPU test replays):
//   device  one thread per pending ray: paged_iteration over the resident
//           levels, the device descriptors and the device pool; per-warp
//           sums of the counters; the pending queue compacted by CUB
//           (DeviceSelect::Flagged keeps the sorted order);
//   copy    the descriptors device -> host (the requests);
//   host    WasRead for the cached pages, the dissertation's LFU swap decision
//           (DevicePoolPlanner), the admitted pages taken from the host
//           cache (read from the file when missing there) into a pinned
//           staging fill;
//   copy    one cudaMemcpyAsync per fill (the page table of the fill and
//           its pages, the dissertation's 1 MB gather), while the host gathers the
//           next fill into the other pinned buffer;
//   device  one block per staged page scatters its 16-byte words to its slot;
//   copy    the descriptors host -> device.
// Before the first iteration one thread per ray makes its state and its
// Garanzha-Loop key and CUB sorts the rays by key (coherent queues, §6.6);
// after the last one a thread per ray writes its answer.
// Everything runs on the default stream in order, so a scatter reads its
// fill after the copy and the next kernel sees the new descriptors.
#include "backend/cuda/paged_device.h"

#include <cuda_runtime.h>

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_select.cuh>

#include <algorithm>
#include <chrono>
#include <mutex>
#include <string>
#include <utility>

#include "backend/backends.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/launch.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

using pack::DeviceRayArrays;
using pack::FreshPages;
using pack::PagedCounters;
using pack::PagedRayState;
using pack::PagedSceneView;
using pack::StagedPage;
using Clock = std::chrono::steady_clock;

constexpr uint32_t kScatterThreads = 256;  // per staged page
constexpr int kCounterFields = 6;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// ------------------------------------------------------------------ kernels

__global__ void start_kernel(DeviceRayArrays a, Box3f bounds, uint32_t count) {
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < count) pack::device_start_step(a, bounds, i);
}

// The counters of a warp summed, one atomic per warp and field: every lane
// of the warp must get here (blocks of kBlockSize, a multiple of 32).
__device__ void add_counters(const PagedCounters& c, unsigned long long* totals) {
    const uint32_t values[kCounterFields] = {c.cells, c.middle, c.pages, c.nodes, c.quads, c.runs};
    for (int f = 0; f < kCounterFields; ++f) {
        const uint32_t sum = __reduce_add_sync(0xFFFFFFFFu, values[f]);
        if ((threadIdx.x & 31u) == 0 && sum != 0) atomicAdd(&totals[f], (unsigned long long)sum);
    }
}

template <bool kAnyHit>
__global__ void iteration_kernel(PagedSceneView view, DeviceRayArrays a, uint32_t count, FreshPages fresh,
                                 unsigned long long* totals) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    PagedCounters c;
    if (k < count) pack::device_iteration_step<kAnyHit>(view, a, k, fresh, c);
    add_counters(c, totals);
}

// Block b copies staged page b of the fill (its table entry first in the fill).
__global__ void scatter_kernel(const uint8_t* fill, uint8_t* slots, uint64_t slot_bytes) {
    const StagedPage e = reinterpret_cast<const StagedPage*>(fill)[blockIdx.x];
    for (uint32_t w = threadIdx.x; w < e.words; w += blockDim.x) pack::scatter_word(fill, e, slots, slot_bytes, w);
}

__global__ void finish_kernel(const PagedRayState* states, uint32_t count, Hit* hits, uint8_t* occluded) {
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < count) pack::device_finish_step(states, i, hits, occluded);
}

// ------------------------------------------------------------ host helpers

// Page-locked host memory (cudaHostAlloc), so copies from it are DMA'd
// asynchronously; freed when it goes.
class PinnedBuffer {
public:
    PinnedBuffer(const std::string& name, size_t bytes) {
        const cudaError_t status = cudaHostAlloc(reinterpret_cast<void**>(&data_), bytes, cudaHostAllocDefault);
        if (status != cudaSuccess) {
            (void)cudaGetLastError();
            throw Error("out of pinned host memory: buffer '" + name + "' asked for " + std::to_string(bytes) +
                        " bytes (" + cudaGetErrorString(status) + ")");
        }
    }
    ~PinnedBuffer() {
        if (data_) cudaFreeHost(data_);
    }
    PinnedBuffer(const PinnedBuffer&) = delete;
    PinnedBuffer& operator=(const PinnedBuffer&) = delete;
    [[nodiscard]] uint8_t* data() const { return data_; }

private:
    uint8_t* data_ = nullptr;
};

// A CUDA event without timing: "this fill's copy is done".
class Event {
public:
    Event() { RF_CUDA_CHECK(cudaEventCreateWithFlags(&event_, cudaEventDisableTiming)); }
    ~Event() { cudaEventDestroy(event_); }
    Event(const Event&) = delete;
    Event& operator=(const Event&) = delete;
    [[nodiscard]] cudaEvent_t get() const { return event_; }

private:
    cudaEvent_t event_ = nullptr;
};

// The largest raw geometry page: the host cache's slot size.
size_t largest_geometry_page(const pack::PackFile& file) {
    uint32_t largest = 1;
    for (uint32_t p = 0; p < file.header().geometry_pages; ++p)
        largest = std::max(largest, file.directory()[p].raw_bytes);
    return largest;
}

// The buffers of a batch of rays, grown (never shrunk) to the largest batch;
// the meter's peak is their largest total.
struct RayBuffers {
    MemoryMeter meter;
    DeviceBuffer<Ray> rays{meter, "paged: rays"};
    DeviceBuffer<PagedRayState> states{meter, "paged: ray states"};
    DeviceBuffer<uint32_t> keys[2] = {{meter, "paged: ray keys"}, {meter, "paged: sorted ray keys"}};
    DeviceBuffer<uint32_t> queue[2] = {{meter, "paged: pending queue"}, {meter, "paged: next pending queue"}};
    DeviceBuffer<uint8_t> again{meter, "paged: asked-for-a-page flags"};
    DeviceBuffer<Hit> hits{meter, "paged: hits"};
    DeviceBuffer<uint8_t> occluded{meter, "paged: occlusion flags"};
    DeviceBuffer<uint32_t> selected{meter, "paged: compaction count", 1};
    DeviceBuffer<unsigned long long> totals{meter, "paged: counters", kCounterFields};
    DeviceBuffer<uint8_t> scratch{meter, "paged: CUB scratch"};

    void reserve(uint32_t n, bool closest) {
        rays.reserve(n);
        states.reserve(n);
        for (auto& b : keys) b.reserve(n);
        for (auto& b : queue) b.reserve(n);
        again.reserve(n);
        if (closest) hits.reserve(n);
        else occluded.reserve(n);
    }
};

}  // namespace

// ------------------------------------------------------------------- engine

struct DevicePagedEngine::Impl {
    Impl(std::shared_ptr<const pack::PackFile> f, const DevicePagedBudgets& budgets, int device_index);

    template <bool kAnyHit>
    class Loop;
    template <bool kAnyHit>
    void run(std::span<const Ray> rays, Hit* hits, uint8_t* occluded);
    [[nodiscard]] size_t resident_bytes() const {
        return pages.bytes() + cell_roots.bytes() + middle_nodes.bytes() + top_nodes.bytes() + top_refs.bytes() +
               instances.bytes();
    }

    std::shared_ptr<const pack::PackFile> file;
    int device = 0;
    pack::StagingLayout layout;
    std::unique_ptr<pack::PageCache> host;
    std::unique_ptr<pack::DevicePoolPlanner> planner;
    // Resident levels, descriptors, staging and pool on the device.
    DeviceBuffer<pack::PageInfo> pages{"paged: page infos"};
    DeviceBuffer<pack::PageNode> page_roots{"paged: page roots"};
    DeviceBuffer<uint32_t> cell_roots{"paged: cell roots"};
    DeviceBuffer<BvhNode> middle_nodes{"paged: middle nodes"};
    DeviceBuffer<pack::PageNode> top_nodes{"paged: top BVH nodes"};
    DeviceBuffer<pack::TopRef> top_refs{"paged: top references"};
    DeviceBuffer<pack::InstanceInfo> instances{"paged: instances"};
    DeviceBuffer<uint32_t> descriptors{"paged: device descriptors"};
    DeviceBuffer<uint32_t> fresh{"paged: pages the last swap admitted"};
    DeviceBuffer<uint8_t> staging{"paged: device staging"};
    DeviceBuffer<uint8_t> pool{"paged: device page pool"};
    // Two pinned fills: the host gathers one while the other is copied.
    std::unique_ptr<PinnedBuffer> fills[2];
    Event fill_copied[2];
    PagedSceneView view;
    RayBuffers rays;
    DevicePagedStats stats;
    std::mutex mutex;  // one query loop at a time
};

DevicePagedEngine::Impl::Impl(std::shared_ptr<const pack::PackFile> f, const DevicePagedBudgets& budgets,
                              int device_index)
    : file(std::move(f)), device(device_index) {
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    const uint32_t page_count = file->header().geometry_pages;
    const size_t host_slot = largest_geometry_page(*file);
    layout = pack::staging_layout(budgets.staging_bytes, pack::round_up_16(host_slot));
    const uint32_t slots = pack::device_slots_within_budget(page_count, layout, budgets.device_bytes);
    host = std::make_unique<pack::PageCache>(*file, 0, page_count, host_slot, budgets.host_bytes, "host geometry cache");
    planner = std::make_unique<pack::DevicePoolPlanner>(page_count, slots);
    pages.upload(file->pages());
    page_roots.upload(file->page_roots());
    cell_roots.upload(file->cell_roots());
    middle_nodes.upload(file->middle_nodes());
    top_nodes.upload(file->top_nodes());
    top_refs.upload(file->top_refs());
    instances.upload(file->instances());
    descriptors.allocate(page_count);
    fresh.allocate(pack::kMaxFreshPages);
    staging.allocate(layout.bytes());
    pool.allocate(size_t(slots) * layout.slot_bytes);
    for (auto& fill : fills) fill = std::make_unique<PinnedBuffer>("paged: staging fill", layout.bytes());
    const pack::PageTableView table{descriptors.data(), pool.data(), layout.slot_bytes, page_count};
    view = pack::make_paged_view(
        *file,
        {pages.data(), page_roots.data(), cell_roots.data(), middle_nodes.data(), top_nodes.data(), top_refs.data(),
         instances.data()},
        table);
}

// The device side of run_device_query_loop: each step one launch or copy.
template <bool kAnyHit>
class DevicePagedEngine::Impl::Loop {
public:
    Loop(Impl& e, std::span<const Ray> rays) : e_(e), rays_(rays) {}

    void begin(uint32_t n) {
        const Clock::time_point start = Clock::now();
        RayBuffers& b = e_.rays;
        b.reserve(n, !kAnyHit);
        RF_CUDA_CHECK(cudaMemcpy(b.rays.data(), rays_.data(), rays_.size_bytes(), cudaMemcpyHostToDevice));
        RF_CUDA_CHECK(cudaMemsetAsync(b.totals.data(), 0, b.totals.bytes()));
        DeviceRayArrays a = arrays(nullptr);
        a.order = b.queue[1].data();
        launch(start_kernel, n, a, e_.file->resident().bounds, n);
        cub_run(b.scratch, [&](void* temp, size_t& bytes) {
            return cub::DeviceRadixSort::SortPairs(temp, bytes, b.keys[0].data(), b.keys[1].data(),
                                                   b.queue[1].data(), b.queue[0].data(), int(n));
        });
        current_ = 0;
        e_.stats.iterate_ms += ms_since(start);
    }

    uint32_t iterate(uint32_t count, std::span<const uint32_t> fresh, bool every_page_fresh) {
        const Clock::time_point start = Clock::now();
        RayBuffers& b = e_.rays;
        FreshPages device_fresh;  // every page by default
        if (!every_page_fresh) {
            if (!fresh.empty())
                RF_CUDA_CHECK(cudaMemcpy(e_.fresh.data(), fresh.data(), fresh.size_bytes(), cudaMemcpyHostToDevice));
            device_fresh = {e_.fresh.data(), uint32_t(fresh.size())};
        }
        launch(iteration_kernel<kAnyHit>, count, e_.view, arrays(b.queue[current_].data()), count, device_fresh,
               b.totals.data());
        cub_run(b.scratch, [&](void* temp, size_t& bytes) {
            return cub::DeviceSelect::Flagged(temp, bytes, b.queue[current_].data(), b.again.data(),
                                              b.queue[1 - current_].data(), b.selected.data(), int(count));
        });
        const uint32_t kept = download_value(b.selected.data());
        current_ = 1 - current_;
        e_.stats.iterate_ms += ms_since(start);
        return kept;
    }

    void download_descriptors(std::span<uint32_t> host) {
        const Clock::time_point start = Clock::now();
        e_.descriptors.download(host);
        e_.stats.manage_ms += ms_since(start);
    }
    void upload_descriptors(std::span<const uint32_t> host) {
        const Clock::time_point start = Clock::now();
        if (!host.empty())
            RF_CUDA_CHECK(cudaMemcpy(e_.descriptors.data(), host.data(), host.size_bytes(), cudaMemcpyHostToDevice));
        e_.stats.manage_ms += ms_since(start);
    }

    // The pinned fill whose last copy is done.
    uint8_t* begin_fill() {
        RF_CUDA_CHECK(cudaEventSynchronize(e_.fill_copied[next_fill_].get()));
        return e_.fills[next_fill_]->data();
    }
    // One copy of the fill (table and pages), then one block per page.
    void end_fill(uint32_t pages, uint64_t bytes) {
        RF_CUDA_CHECK(cudaMemcpyAsync(e_.staging.data(), e_.fills[next_fill_]->data(), bytes, cudaMemcpyHostToDevice));
        RF_CUDA_CHECK(cudaEventRecord(e_.fill_copied[next_fill_].get()));
        launch_shaped(scatter_kernel, LaunchShape{pages, kScatterThreads}, e_.staging.data(), e_.pool.data(),
                      e_.layout.slot_bytes);
        next_fill_ = 1 - next_fill_;
    }

    void finish(uint32_t n) {
        RayBuffers& b = e_.rays;
        launch(finish_kernel, n, b.states.data(), n, kAnyHit ? nullptr : b.hits.data(),
               kAnyHit ? b.occluded.data() : nullptr);
        unsigned long long totals[kCounterFields];
        RF_CUDA_CHECK(cudaMemcpy(totals, b.totals.data(), sizeof totals, cudaMemcpyDeviceToHost));
        DevicePagedStats& s = e_.stats;
        s.cells += totals[0];
        s.middle += totals[1];
        s.pages += totals[2];
        s.nodes += totals[3];
        s.quads += totals[4];
        s.runs += totals[5];
    }

private:
    DeviceRayArrays arrays(const uint32_t* pending) const {
        RayBuffers& b = e_.rays;
        return {b.rays.data(), b.states.data(), b.keys[0].data(), nullptr, pending, b.again.data()};
    }

    Impl& e_;
    std::span<const Ray> rays_;
    int current_ = 0;    // the pending queue: rays.queue[current_]
    int next_fill_ = 0;  // the pinned fill to write next
};

template <bool kAnyHit>
void DevicePagedEngine::Impl::run(std::span<const Ray> batch, Hit* hits_out, uint8_t* occluded_out) {
    const std::lock_guard<std::mutex> lock(mutex);
    if (batch.size() > uint64_t(INT32_MAX)) throw Error("paged device queries: more than 2^31 rays in one batch");
    RF_CUDA_CHECK(cudaSetDevice(device));
    const uint32_t n = uint32_t(batch.size());
    Loop<kAnyHit> loop(*this, batch);
    pack::run_device_query_loop(loop, *planner, layout, *host, *file, n, stats.loop);
    stats.device_pool = planner->stats();
    if (n == 0) return;
    if (hits_out) rays.hits.download(std::span<Hit>(hits_out, n));
    if (occluded_out) rays.occluded.download(std::span<uint8_t>(occluded_out, n));
}

DevicePagedEngine::DevicePagedEngine(std::shared_ptr<const pack::PackFile> file, const DevicePagedBudgets& budgets,
                                     int device)
    : impl_(std::make_unique<Impl>(std::move(file), budgets, device)) {}

DevicePagedEngine::~DevicePagedEngine() = default;

void DevicePagedEngine::intersect(std::span<const Ray> rays, std::span<Hit> hits) {
    if (hits.size() < rays.size()) throw Error("paged device queries: fewer hits than rays");
    impl_->run<false>(rays, hits.data(), nullptr);
}

void DevicePagedEngine::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) {
    if (occluded.size() < rays.size()) throw Error("paged device queries: fewer occlusion flags than rays");
    impl_->run<true>(rays, nullptr, occluded.data());
}

const pack::PackFile& DevicePagedEngine::file() const { return *impl_->file; }
uint32_t DevicePagedEngine::device_slot_count() const { return impl_->planner->slot_count(); }
uint32_t DevicePagedEngine::device_cached_count() const { return impl_->planner->cached_count(); }
size_t DevicePagedEngine::device_cache_bytes() const {
    return impl_->descriptors.bytes() + impl_->staging.bytes() + impl_->pool.bytes();
}
size_t DevicePagedEngine::device_resident_bytes() const { return impl_->resident_bytes(); }
size_t DevicePagedEngine::device_ray_bytes_peak() const { return impl_->rays.meter.peak(); }
size_t DevicePagedEngine::host_bytes() const {
    return impl_->host->memory_bytes() + impl_->planner->memory_bytes() + 2 * impl_->layout.bytes();
}
const pack::PageCache& DevicePagedEngine::host_cache() const { return *impl_->host; }
std::span<const uint32_t> DevicePagedEngine::device_descriptors() const { return impl_->planner->descriptors(); }
const DevicePagedStats& DevicePagedEngine::stats() const { return impl_->stats; }

void DevicePagedEngine::reset_stats() {
    const std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->stats = {};
    impl_->planner->reset_stats();
    impl_->host->reset_stats();
}

void DevicePagedEngine::clear_caches() {
    const std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->planner->clear();  // uploaded by the next loop
    impl_->host->clear();
}

}  // namespace rf::cuda
