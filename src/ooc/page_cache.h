// One page manager on the CPU (Garanzha 2014, §6.2, adapted from host ->
// GPU to disk -> host memory): a pool of slots in this process's memory,
// filled by explicit reads of the pack file (pread), so the resident set is
// the pool plus the tables and is bounded by the budget.
//
// The loop it serves (Listing 6.1): rays run an iteration, marking pages
// they use or need (PageTableView::request); then swap_requested_pages()
//   1. zeroes all TimeUsed every 10th call (recent use weighs more), then
//      counts TimeUsed up (saturating at 31) for every cached page marked
//      Requested (so a page used in the 10th iteration keeps that use);
//   2. if requested pages are missing: when the free slots hold them all,
//      they go there (no sort: the cache is filling up); otherwise sorts
//      the page ids by the LFU key (cached: TimeUsed; missing and
//      requested: 32; missing: 64) with a stable counting sort, and admits
//      the first min(requested, slots) requested pages in that order, into
//      the free slots and the slots of as many least used cached pages
//      (Garanzha 2014's swap of pageIDs[0, k) with pageIDs[cached, cached + k));
//      pages beyond the pool are deferred: their rays ask again;
//   3. reads the admitted pages (in parallel), verifies them, updates the
//      descriptors (a new page: its slot, TimeUsed 0, WasRead 0); clears
//      Requested everywhere.
// After a swap the cached prefix of the page ids lists the admitted pages
// first (in the order above), then the cached pages that stayed, in their
// (sorted) order, so that among equal keys the pages admitted last are
// evicted first, as with Garanzha 2014's swap. A page that fails to read
// (rf::Error, thrown after the bookkeeping, the other pages of the call
// loaded) stays out of core and its slot becomes free.
// It returns how many pages it loaded; 0 with requests pending cannot
// happen unless a read failed (a request always gets a slot, the pool has
// at least one).
//
// Threads: during an iteration any number of threads may call the view's
// request, cached and was_read; the member functions here are called
// between iterations, by one thread.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "ooc/pack_file.h"
#include "ooc/page_table.h"
#include "ooc/uring_reader.h"

namespace rf::pack {

struct PageCacheStats {
    uint64_t requests = 0;       // pages marked Requested over all swaps (cached uses + misses)
    uint64_t hits = 0;           // ... of which were cached
    uint64_t misses = 0;         // ... of which were not cached (loaded, or deferred: counted again when asked again)
    uint64_t pages_read = 0;
    uint64_t bytes_read = 0;     // from the file (stored bytes)
    uint64_t evictions = 0;
    uint64_t swaps = 0;          // swap_requested_pages calls
    double io_ms = 0.0;          // reading and decompressing
    double manage_ms = 0.0;      // the rest of swap_requested_pages (counting, sorting, tables)
    [[nodiscard]] double hit_rate() const { return requests ? double(hits) / double(requests) : 1.0; }
};

// The largest raw page of `file`'s directory entries [first, first + count)
// rounded up to 16 bytes: the size of a cache slot for them (at least 16).
size_t largest_raw_page(const PackFile& file, uint64_t first, uint64_t count);

class PageCache {
public:
    // What the manager holds besides the pool: per page a descriptor, a
    // page id, the sort's output and a flag; per slot its page, a free-list
    // entry, a load, a loaded page and a sort key.
    static constexpr size_t kTableBytesPerPage = 3 * sizeof(uint32_t) + 1;
    static constexpr size_t kBookkeepingBytesPerSlot = 3 * sizeof(uint32_t) + 12 + 1;

    // Pages [first_page, first_page + page_count) of `file`'s directory,
    // each at most slot_bytes raw; as many slots as fit in budget_bytes
    // together with the tables (kTableBytesPerPage per page,
    // kBookkeepingBytesPerSlot per slot), but no more than page_count. At
    // least one (none when page_count is 0); rf::Error naming `name` when
    // one slot does not fit, more than kMaxSlots would, the range is not in
    // the directory or a page is larger than a slot. Pages are read on TBB's
    // threads (the caller's arena).
    PageCache(const PackFile& file, uint64_t first_page, uint32_t page_count, size_t slot_bytes, size_t budget_bytes,
              std::string name);
    // The budget that holds all `page_count` pages at once (tables included):
    // a larger one leaves the rest unused.
    [[nodiscard]] static uint64_t budget_for_all(uint32_t page_count, size_t slot_bytes) {
        return uint64_t(page_count) * (kTableBytesPerPage + slot_bytes + kBookkeepingBytesPerSlot);
    }
    ~PageCache();
    PageCache(const PageCache&) = delete;
    PageCache& operator=(const PageCache&) = delete;

    [[nodiscard]] PageTableView view() { return view_; }
    [[nodiscard]] const std::string& name() const { return name_; }
    [[nodiscard]] uint32_t page_count() const { return view_.page_count; }
    [[nodiscard]] uint32_t slot_count() const { return slot_count_; }
    [[nodiscard]] size_t slot_bytes() const { return size_t(view_.slot_bytes); }
    [[nodiscard]] uint32_t cached_count() const { return cached_count_; }

    // See above. Returns the pages loaded.
    size_t swap_requested_pages();
    // The pages the last swap loaded.
    [[nodiscard]] std::span<const uint32_t> last_loaded() const { return last_loaded_; }
    // WasRead := 1 for every cached page (after an iteration of a query loop)...
    void mark_cached_as_read();
    // ... and := 0 for all (at the start of a query loop).
    void clear_was_read();
    // Every page out, TimeUsed and flags cleared (stats kept).
    void clear();

    [[nodiscard]] const PageCacheStats& stats() const { return stats_; }
    void reset_stats() { stats_ = {}; }
    // The pool and the tables: what this manager holds in memory.
    [[nodiscard]] size_t memory_bytes() const;

private:
    // A page being loaded by this call, into `slot`.
    struct Admission {
        uint32_t page = 0;
        uint32_t slot = 0;
        bool ok = false;  // read and verified
    };
    static_assert(sizeof(Admission) == 12);

    uint32_t count_requests();
    void admit_to_free_slots(uint32_t missing);
    void admit_least_used_out(uint32_t missing);
    void sort_by_lfu_key(uint32_t missing);
    bool take_requested_missing(uint32_t page);
    void evict(uint32_t page);
    std::string read_admissions();
    std::vector<UringReader::Read> uring_reads();
    size_t settle_admissions();
    void move_failed_to_missing(uint32_t prefix);

    const PackFile& file_;
    uint64_t first_page_ = 0;
    std::string name_;
    uint32_t slot_count_ = 0;
    uint32_t cached_count_ = 0;
    uint32_t calls_ = 0;                   // swaps since construction or clear(), for the TimeUsed reset
    std::unique_ptr<uint8_t[]> pool_;
    std::vector<uint32_t> descriptors_;
    // pageIDs of §6.2: the cached pages first (page_ids_[0, cached_count_)),
    // then the missing ones. While tail_in_page_order_ (no sort and no
    // failed read since construction or clear()) the missing ones are in
    // page order and only the cached prefix is kept; the tail is written
    // from the descriptors when the first sort needs it.
    std::vector<uint32_t> page_ids_;
    std::vector<uint32_t> sorted_ids_;     // the sort's output, then swapped with page_ids_
    std::vector<uint8_t> requested_missing_;  // per page: set in step 1, cleared as the page is placed
    std::vector<uint8_t> prefix_keys_;     // TimeUsed of page_ids_[i] for the sort of the cached prefix
    bool tail_in_page_order_ = true;
    std::vector<uint32_t> free_slots_;     // a stack, slot 0 on top at first
    std::vector<uint32_t> slot_page_;      // page held by each slot (or kNoPage)
    std::vector<Admission> admissions_;    // this call's loads, at most slot_count_
    // io_uring reads: each admission's stored bytes (in its slot for a raw
    // page, in stored_ otherwise) and the errno of a read not made.
    std::vector<std::vector<uint8_t>> stored_;
    std::vector<int> read_errors_;
    std::vector<uint32_t> last_loaded_;    // the pages of the admissions that loaded
    PageTableView view_;
    bool evicted_read_ = false;  // some missing page holds WasRead (see evict)
    PageCacheStats stats_;
};

}  // namespace rf::pack
