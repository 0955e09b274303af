// The GPU's geometry page manager and query loop for a paged scene
// (Garanzha 2014, §6.2, Listing 6.1 and §6.3.3),
// written once for the CUDA backend (backend/cuda/paged_device.cu) and its
// CPU replay (tests/paged_device_logic_test.cpp): two levels, host memory ->
// device memory, with the host level itself a PageCache filled from disk.
//
//   - per-item steps (RF_HD, one thread each on the device): a ray's start
//     (fresh state, sort key), its iteration (paged_iteration itself), its
//     result, and the scatter of one 16-byte word of a staged page into its
//     slot;
//   - DevicePoolPlanner (host): the dissertation's swap decision for the device pool
//     over a host mirror of the device's descriptors: uses counted into
//     TimeUsed (reset every 10th call), free slots first while the pool
//     fills, else the stable sort by the LFU key (cached: TimeUsed,
//     requested: 32, others: 64) and k = min(requested, slots) pages
//     admitted into the free slots and those of the least used cached pages;
//     evicted pages keep WasRead (see PageCache::evict); deferred requests
//     come back in later iterations;
//   - stage_admissions (host): the admitted pages taken from the host cache
//     (read from the file first when missing there) and gathered into a
//     staging area, one host -> device copy and one scatter per fill (Fig. 6.1);
//   - run_device_query_loop: the loop itself over a Backend supplying the
//     launches and copies (see there).
//
// Why the decision runs on the host: the device's descriptors are copied to
// the host anyway to find the requested pages (the dissertation's "array
// of requested page indices"), and the host level must be asked for them;
// the dissertation sorts on the GPU, at the cost of a radix sort per swap.
// One pass over the page ids here is a counting sort, as cheap as the copy.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <span>
#include <string>
#include <vector>

#include "core/assert.h"
#include "ooc/pack_file.h"
#include "ooc/page_cache.h"
#include "ooc/page_table.h"
#include "ooc/paged_traversal.h"
#include "rayforge/core/error.h"
#include "rayforge/core/host_device.h"
#include "render/ray_sort_key.h"

namespace rf::pack {

// ------------------------------------------------------------ per-item steps

// The ray arrays of one query loop (device buffers, or host vectors in the replay).
struct DeviceRayArrays {
    const Ray* rays = nullptr;
    PagedRayState* states = nullptr;
    uint32_t* keys = nullptr;      // by ray, then sorted
    uint32_t* order = nullptr;     // by ray: iota, sorted by key into the first pending queue
    const uint32_t* pending = nullptr;
    uint8_t* again = nullptr;      // by queue position: asked for a page
};

// Ray i before the first iteration: a fresh state and its coherence key.
RF_HDI void device_start_step(const DeviceRayArrays& a, const Box3f& bounds, uint32_t i) {
    a.states[i] = PagedRayState{};
    a.keys[i] = ray_sort_key(a.rays[i], bounds);
    a.order[i] = i;
}

// Queue position k in an iteration: the ray's paged_iteration (`fresh`:
// the pages the last swap admitted, in device memory).
template <bool kAnyHit>
RF_HDI void device_iteration_step(const PagedSceneView& v, const DeviceRayArrays& a, uint32_t k,
                                  const FreshPages& fresh, PagedCounters& counters) {
    const uint32_t i = a.pending[k];
    a.again[k] = paged_iteration<kAnyHit>(v, a.rays[i], a.states[i], counters, fresh) ? 1 : 0;
}

// Ray i's answer, as PagedEngine gives it.
RF_HDI void device_finish_step(const PagedRayState* states, uint32_t i, Hit* hits, uint8_t* occluded) {
    if (hits) hits[i] = states[i].hit.found() ? states[i].hit : Hit{};
    if (occluded) occluded[i] = states[i].occluded ? 1 : 0;
}

// A page in a staging fill: its bytes at `offset` (16-aligned) of the fill,
// `words` 16-byte words of them, bound for `slot`.
struct StagedPage {
    uint64_t offset = 0;
    uint32_t slot = 0;
    uint32_t words = 0;
};
static_assert(sizeof(StagedPage) == 16);

inline constexpr uint64_t kStagingWord = 16;

// Word w of staged page e into its slot (slots are a multiple of 16 bytes
// apart, so every word is aligned on both sides).
RF_HDI void scatter_word(const uint8_t* fill, const StagedPage& e, uint8_t* slots, uint64_t slot_bytes, uint32_t w) {
    const uint8_t* from = fill + e.offset + uint64_t(w) * kStagingWord;
    uint8_t* to = slots + uint64_t(e.slot) * slot_bytes + uint64_t(w) * kStagingWord;
#if defined(__CUDA_ARCH__)
    *reinterpret_cast<uint4*>(to) = *reinterpret_cast<const uint4*>(from);  // one 128-bit load and store
#else
    std::memcpy(to, from, kStagingWord);
#endif
}

// ----------------------------------------------------------------- layouts

[[nodiscard]] inline uint64_t round_up_16(uint64_t bytes) { return (bytes + 15) & ~uint64_t(15); }

// A staging fill: the StagedPage table of up to max_pages pages, then the
// pages packed at 16-byte boundaries; one copy carries both.
struct StagingLayout {
    uint32_t max_pages = 1;
    uint64_t slot_bytes = 16;
    [[nodiscard]] uint64_t table_bytes() const { return round_up_16(uint64_t(max_pages) * sizeof(StagedPage)); }
    [[nodiscard]] uint64_t bytes() const { return table_bytes() + uint64_t(max_pages) * slot_bytes; }
};

// Garanzha 2014's gather array: 1 MB, or one page when pages are larger.
inline constexpr uint64_t kDefaultStagingBytes = uint64_t(1) << 20;

[[nodiscard]] inline StagingLayout staging_layout(uint64_t staging_bytes, uint64_t slot_bytes) {
    return {uint32_t(std::clamp<uint64_t>(staging_bytes / slot_bytes, 1, 4096)), slot_bytes};
}

// The device's share of a budget: a descriptor per page, the staging area,
// and the pool. Slots that fit (at most one per page); rf::Error naming
// the numbers when none does or more than a descriptor can address would.
[[nodiscard]] inline uint32_t device_slots_within_budget(uint32_t page_count, const StagingLayout& staging,
                                                         uint64_t budget_bytes) {
    if (page_count == 0) return 0;
    const uint64_t fixed = uint64_t(page_count) * sizeof(uint32_t) + staging.bytes();
    const uint64_t fit = budget_bytes > fixed ? (budget_bytes - fixed) / staging.slot_bytes : 0;
    if (fit == 0)
        throw Error("device geometry cache: a budget of " + std::to_string(budget_bytes) +
                    " bytes holds no slot (descriptors and staging take " + std::to_string(fixed) + " bytes, a slot " +
                    std::to_string(staging.slot_bytes) + ")");
    const uint64_t slots = std::min<uint64_t>(fit, page_count);
    if (slots > kMaxSlots)
        throw Error("device geometry cache: " + std::to_string(slots) + " slots, more than the " +
                    std::to_string(kMaxSlots) + " a descriptor can address");
    return uint32_t(slots);
}

// The budget that gives exactly `slots` device slots (tests, the bench).
[[nodiscard]] inline uint64_t device_budget_for_slots(uint32_t page_count, const StagingLayout& staging,
                                                      uint32_t slots) {
    return uint64_t(page_count) * sizeof(uint32_t) + staging.bytes() + uint64_t(slots) * staging.slot_bytes;
}

// The resident levels and a page table as the per-ray code sees them, with
// PagedEngine::view()'s arithmetic (the same cell sizes to the bit).
// Where the resident levels lie for the rays (host or device copies of the
// file's arrays).
struct ResidentArrays {
    const PageInfo* pages = nullptr;
    const PageNode* page_roots = nullptr;
    const uint32_t* cell_roots = nullptr;
    const BvhNode* middle_nodes = nullptr;
    const PageNode* top_nodes = nullptr;  // null when the file has no top BVH
    const TopRef* top_refs = nullptr;
    const InstanceInfo* instances = nullptr;
};

[[nodiscard]] inline PagedSceneView make_paged_view(const PackFile& f, const ResidentArrays& a, PageTableView geometry) {
    const ResidentHeader& r = f.resident();
    PagedSceneView v;
    v.pages = a.pages;
    v.page_roots = a.page_roots;
    v.cell_roots = a.cell_roots;
    v.middle_nodes = a.middle_nodes;
    v.refs = a.top_refs;
    v.instances = a.instances;
    if (!f.top_nodes().empty()) v.top_nodes = a.top_nodes;
    for (int a3 = 0; a3 < 3; ++a3)
        v.coord_scale = std::max({v.coord_scale, std::fabs(r.bounds.lo[a3]), std::fabs(r.bounds.hi[a3])});
    v.geometry = geometry;
    v.grid_bounds = r.grid_bounds;
    for (int a3 = 0; a3 < 3; ++a3) v.res[a3] = r.grid_res[a3];
    v.cell_size = (r.grid_bounds.hi - r.grid_bounds.lo) / Vec3f(float(v.res[0]), float(v.res[1]), float(v.res[2]));
    v.page_count = uint32_t(f.pages().size());
    return v;
}

// ------------------------------------------------------- the swap decision

// A page admitted to the device pool by a swap.
struct SlotAdmission {
    uint32_t page = 0;
    uint32_t slot = 0;
};

struct DevicePoolStats {
    uint64_t requests = 0;   // pages marked Requested over all swaps
    uint64_t hits = 0;       // ... of which were cached on the device
    uint64_t misses = 0;     // ... of which were not (admitted, or deferred and counted again)
    uint64_t admitted = 0;
    uint64_t evictions = 0;
    uint64_t swaps = 0;
    [[nodiscard]] double hit_rate() const { return requests ? double(hits) / double(requests) : 1.0; }
};

// The LFU key of a descriptor (Fig. 6.2), as a bucket of the counting sort:
// TimeUsed 0-31 for a cached page, 32 for a requested missing one, 33 (the
// dissertation's 64) for the others.
[[nodiscard]] RF_HDI uint32_t lfu_bucket(uint32_t d) {
    if (!(d & kOutOfCore)) return (d & kTimeMask) >> kTimeShift;
    return (d & kRequested) ? kTimeMax + 1 : kTimeMax + 2;
}
inline constexpr uint32_t kLfuBuckets = kTimeMax + 3;

// One more use in TimeUsed, saturating at 31.
[[nodiscard]] RF_HDI uint32_t count_use(uint32_t d) {
    return (d & kTimeMask) == kTimeMask ? d : d + (1u << kTimeShift);
}

// The device pool's manager, on the host: a mirror of the device's
// descriptors (downloaded after each kernel, uploaded after each swap), the
// page ids of §6.2 (cached first), the free slots and each slot's page.
// Between swaps the mirror and the device agree.
class DevicePoolPlanner {
public:
    static constexpr uint32_t kTimeResetPeriod = 10;  // swaps between TimeUsed resets (Garanzha 2014's example)
    static constexpr uint32_t kNoPage = 0xFFFFFFFFu;

    DevicePoolPlanner(uint32_t page_count, uint32_t slot_count) : slot_count_(slot_count) {
        RF_ASSERT(slot_count <= page_count && (slot_count > 0 || page_count == 0), "one slot at least, one per page at most");
        descriptors_.assign(page_count, kOutOfCore);
        page_ids_.resize(page_count);
        sorted_.resize(page_count);
        slot_page_.resize(slot_count);
        admissions_.reserve(slot_count);
        clear();
    }

    [[nodiscard]] std::span<uint32_t> descriptors() { return descriptors_; }
    [[nodiscard]] std::span<const uint32_t> descriptors() const { return descriptors_; }
    [[nodiscard]] uint32_t page_count() const { return uint32_t(descriptors_.size()); }
    [[nodiscard]] uint32_t slot_count() const { return slot_count_; }
    [[nodiscard]] uint32_t cached_count() const { return cached_; }
    [[nodiscard]] uint32_t slot_page(uint32_t slot) const { return slot_page_[slot]; }
    [[nodiscard]] const DevicePoolStats& stats() const { return stats_; }
    void reset_stats() { stats_ = {}; }
    // The host tables above.
    [[nodiscard]] size_t memory_bytes() const {
        return sizeof(uint32_t) * (descriptors_.capacity() + page_ids_.capacity() + sorted_.capacity() +
                                   free_slots_.capacity() + slot_page_.capacity()) +
               sizeof(SlotAdmission) * admissions_.capacity();
    }

    // The swap decision over the mirror (see the file's comment): the pages
    // to copy into the device pool, each with its slot. The mirror already
    // says they are cached there (TimeUsed 0, no flags): upload it once they are.
    std::span<const SlotAdmission> swap_requested_pages() {
        ++stats_.swaps;
        if (++calls_ % kTimeResetPeriod == 0)
            for (uint32_t page : slot_page_)
                if (page != kNoPage) descriptors_[page] &= ~kTimeMask;
        admissions_.clear();
        const uint32_t missing = count_requests();
        if (missing == 0) return {};
        if (missing <= free_slots_.size())
            admit_to_free_slots();
        else
            admit_least_used_out(missing);
        for (const SlotAdmission& a : admissions_) {
            descriptors_[a.page] = a.slot;
            slot_page_[a.slot] = a.page;
        }
        cached_ += uint32_t(admissions_.size());
        stats_.admitted += admissions_.size();
        return admissions_;
    }

    // WasRead for every cached page, after each kernel...
    void mark_cached_as_read() {
        for (uint32_t page : slot_page_)
            if (page != kNoPage) descriptors_[page] |= kWasRead;
    }
    // ... and off for all pages (evicted ones keep it) when a loop starts.
    void clear_was_read() {
        for (uint32_t& d : descriptors_) d &= ~kWasRead;
    }
    // Every page out (an empty pool, as after construction; stats kept).
    void clear() {
        std::fill(descriptors_.begin(), descriptors_.end(), kOutOfCore);
        for (uint32_t p = 0; p < page_count(); ++p) page_ids_[p] = p;
        std::fill(slot_page_.begin(), slot_page_.end(), kNoPage);
        free_slots_.clear();
        for (uint32_t slot = slot_count_; slot-- > 0;) free_slots_.push_back(slot);  // slot 0 on top
        cached_ = 0;
        calls_ = 0;
    }

private:
    // Uses of cached pages into TimeUsed (their Requested cleared); the
    // number of requested missing pages, whose bit stays for the sort.
    uint32_t count_requests() {
        uint32_t missing = 0;
        for (uint32_t& d : descriptors_) {
            if (!(d & kRequested)) continue;
            ++stats_.requests;
            if (d & kOutOfCore) {
                ++missing;
            } else {
                ++stats_.hits;
                d = count_use(d) & ~kRequested;
            }
        }
        stats_.misses += missing;
        return missing;
    }

    // The pool has room for every request (§2.12 note 1: no sort while it
    // fills): the requested pages in the order of the missing ones, each
    // into the next free slot; page ids [admitted | cached | other missing].
    void admit_to_free_slots() {
        uint32_t out = 0;
        for (uint32_t i = cached_; i < page_count(); ++i)
            if (descriptors_[page_ids_[i]] & kRequested) {
                const uint32_t page = page_ids_[i];
                admissions_.push_back({page, free_slots_.back()});
                free_slots_.pop_back();
                sorted_[out++] = page;
            }
        std::copy(page_ids_.begin(), page_ids_.begin() + cached_, sorted_.begin() + out);
        out += cached_;
        for (uint32_t i = cached_; i < page_count(); ++i)
            if (!(descriptors_[page_ids_[i]] & kRequested)) sorted_[out++] = page_ids_[i];
        page_ids_.swap(sorted_);
    }

    // Garanzha 2014's LFU swap: after the stable sort the page ids are [cached,
    // least used first | requested | others]; the first k requested take
    // the free slots and the slots of the `evicted` least used pages
    // (pageIDs[0, evicted) swapped with pageIDs[cached, cached + evicted)),
    // the rest are deferred. Page ids become [admitted | cached that stay |
    // evicted | deferred and others], so that among equal keys the pages
    // admitted last are evicted first.
    void admit_least_used_out(uint32_t missing) {
        sort_by_lfu_key();
        const uint32_t k = std::min(missing, slot_count_);
        const uint32_t evicted = k - uint32_t(free_slots_.size());  // missing > free slots, so k >= free slots
        RF_ASSERT(evicted <= cached_, "the pool holds the cached pages and the free slots");
        for (uint32_t i = 0; i < k; ++i) {
            const uint32_t page = page_ids_[cached_ + i];
            if (i < evicted) {
                admissions_.push_back({page, evict(page_ids_[i])});
            } else {
                admissions_.push_back({page, free_slots_.back()});
                free_slots_.pop_back();
            }
        }
        for (uint32_t i = cached_ + k; i < cached_ + missing; ++i) descriptors_[page_ids_[i]] &= ~kRequested;
        const auto ids = page_ids_.begin();
        auto out = std::copy(ids + cached_, ids + cached_ + k, sorted_.begin());
        out = std::copy(ids + evicted, ids + cached_, out);
        out = std::copy(ids, ids + evicted, out);
        std::copy(ids + cached_ + k, page_ids_.end(), out);
        page_ids_.swap(sorted_);
        cached_ -= evicted;
    }

    // The stable sort of the page ids by the LFU key, as a counting sort
    // over its 34 values.
    void sort_by_lfu_key() {
        uint32_t start[kLfuBuckets + 1] = {};
        for (uint32_t page : page_ids_) ++start[lfu_bucket(descriptors_[page]) + 1];
        for (uint32_t b = 1; b <= kLfuBuckets; ++b) start[b] += start[b - 1];
        for (uint32_t page : page_ids_) sorted_[start[lfu_bucket(descriptors_[page])]++] = page;
        page_ids_.swap(sorted_);
    }

    // An evicted page keeps WasRead: every ray of this loop has searched it
    // (PageCache::evict says why). Returns its slot.
    uint32_t evict(uint32_t page) {
        const uint32_t slot = descriptors_[page] & kSlotMask;
        slot_page_[slot] = kNoPage;
        descriptors_[page] = kOutOfCore | (descriptors_[page] & kWasRead);
        ++stats_.evictions;
        return slot;
    }

    uint32_t slot_count_ = 0;
    uint32_t cached_ = 0;
    uint32_t calls_ = 0;
    std::vector<uint32_t> descriptors_;
    std::vector<uint32_t> page_ids_;  // cached pages first (page_ids_[0, cached_))
    std::vector<uint32_t> sorted_;    // the next order, then swapped in
    std::vector<uint32_t> free_slots_;
    std::vector<uint32_t> slot_page_;
    std::vector<SlotAdmission> admissions_;
    DevicePoolStats stats_;
};

// ------------------------------------------------------------- the loop

struct DeviceLoopStats {
    uint64_t queries = 0;
    uint64_t iterations = 0;
    uint64_t ray_iterations = 0;  // sum over iterations of the rays pending in it (running or waiting for their page)
    uint64_t fills = 0;           // staging fills: host -> device copies
    uint64_t pages_staged = 0;
    uint64_t bytes_staged = 0;    // copied host -> device (tables and pages)
    uint64_t host_swaps = 0;      // host cache swaps asked for by staging
    double swap_ms = 0.0;         // the swap decisions (host)
    double staging_ms = 0.0;      // host cache, gather, and issuing the copies and scatters
};

namespace detail {
inline double ms_between(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}
}  // namespace detail

// Gathers the admitted pages into staging fills of at most
// min(layout.max_pages, host slots) pages, then hands each fill to the
// backend (one copy, one scatter). A page is copied out of the host cache
// while it is there: first the pages of the fill the host already holds
// (marked as used there), then, after one host swap that loads the others
// (at most its slot count, so all are admitted, whatever it evicts), those.
// Backend: `uint8_t* begin_fill()` (a fill the host may write) and
// `void end_fill(uint32_t pages, uint64_t bytes)`.
template <class Backend>
void stage_admissions(Backend& backend, const StagingLayout& layout, PageCache& host, const PackFile& file,
                      std::span<const SlotAdmission> admitted, DeviceLoopStats& stats) {
    const std::span<const PageEntry> directory = file.directory();
    const size_t per_fill = std::min<size_t>(layout.max_pages, host.slot_count());
    RF_ASSERT(per_fill > 0 || admitted.empty(), "a page admitted from a host cache without slots");
    std::vector<uint32_t> missing;
    for (size_t first = 0; first < admitted.size(); first += per_fill) {
        const std::span<const SlotAdmission> fill_pages = admitted.subspan(first, std::min(per_fill, admitted.size() - first));
        uint8_t* fill = backend.begin_fill();
        auto* table = reinterpret_cast<StagedPage*>(fill);
        uint64_t offset = layout.table_bytes();
        for (uint32_t j = 0; j < fill_pages.size(); ++j) {
            const uint64_t raw = directory[fill_pages[j].page].raw_bytes;
            table[j] = {offset, fill_pages[j].slot, uint32_t(round_up_16(raw) / kStagingWord)};
            offset += round_up_16(raw);
        }
        const auto copy_out = [&](uint32_t j) {
            const uint8_t* bytes = host.view().cached(fill_pages[j].page);
            if (!bytes) throw Error(file.path() + ": host cache lost page " + std::to_string(fill_pages[j].page));
            std::memcpy(fill + table[j].offset, bytes, directory[fill_pages[j].page].raw_bytes);
        };
        missing.clear();
        for (uint32_t j = 0; j < fill_pages.size(); ++j) {
            host.view().request(fill_pages[j].page);
            if (host.view().cached(fill_pages[j].page)) copy_out(j);
            else missing.push_back(j);
        }
        if (!missing.empty()) {
            host.swap_requested_pages();
            ++stats.host_swaps;
            for (uint32_t j : missing) copy_out(j);
        }
        backend.end_fill(uint32_t(fill_pages.size()), offset);
        ++stats.fills;
        stats.pages_staged += fill_pages.size();
        stats.bytes_staged += offset;
    }
}

// The query loop of Listing 6.1 for the device pool, over a Backend:
//   void begin(uint32_t rays)        fresh states and keys, rays sorted by key into the pending queue
//   uint32_t iterate(uint32_t count, std::span<const uint32_t> fresh, bool every_page_fresh)
//                                    one iteration over the queue's `count` rays (`fresh`: the
//                                    pages the last swap admitted, unless every_page_fresh), the
//                                    queue compacted to those that asked for a page; returns their count
//   void download_descriptors(std::span<uint32_t>), void upload_descriptors(std::span<const uint32_t>)
//   uint8_t* begin_fill(), void end_fill(uint32_t pages, uint64_t bytes)   (stage_admissions)
//   void finish(uint32_t rays)       the answers
// After each iteration: the descriptors to the host, WasRead for the cached
// pages, the swap, the admitted pages staged and scattered, the descriptors
// back. A failure of the host level (a corrupted page) empties the device
// pool before the error goes on.
template <class Backend>
void run_device_query_loop(Backend& backend, DevicePoolPlanner& planner, const StagingLayout& layout,
                           PageCache& host, const PackFile& file, uint32_t ray_count, DeviceLoopStats& stats) {
    stats.queries += ray_count;
    if (ray_count == 0) return;
    backend.begin(ray_count);
    planner.clear_was_read();
    backend.upload_descriptors(planner.descriptors());
    // WasRead survives eviction, so a page is admitted at most once per loop.
    const uint64_t iteration_limit = uint64_t(planner.page_count()) + 2;
    uint32_t pending = ray_count;
    std::vector<uint32_t> fresh;  // the pages the last swap admitted
    bool every_page_fresh = true;  // the first iteration (fresh rays), and after a large swap
    for (uint64_t iteration = 0; pending > 0; ++iteration) {
        if (iteration > iteration_limit)
            throw Error(file.path() + ": device paged query loop did not converge (a page manager bug)");
        ++stats.iterations;
        stats.ray_iterations += pending;
        pending = backend.iterate(pending, fresh, every_page_fresh);
        backend.download_descriptors(planner.descriptors());
        planner.mark_cached_as_read();
        size_t admitted = 0;
        try {
            const auto start = std::chrono::steady_clock::now();
            const std::span<const SlotAdmission> admissions = planner.swap_requested_pages();
            const auto decided = std::chrono::steady_clock::now();
            admitted = admissions.size();
            every_page_fresh = admitted > kMaxFreshPages;
            fresh.clear();
            if (!every_page_fresh)
                for (const SlotAdmission& a : admissions) fresh.push_back(a.page);
            stage_admissions(backend, layout, host, file, admissions, stats);
            stats.swap_ms += detail::ms_between(start, decided);
            stats.staging_ms += detail::ms_between(decided, std::chrono::steady_clock::now());
        } catch (...) {
            planner.clear();  // the pool's contents are unknown; the next loop uploads the empty table
            throw;
        }
        if (pending == 0) break;  // the mirror holds the last uses; the next loop uploads it
        if (admitted == 0)
            throw Error(file.path() + ": device paged query loop made no progress (page manager admitted nothing)");
        backend.upload_descriptors(planner.descriptors());
    }
    backend.finish(ray_count);
}

}  // namespace rf::pack
