// One page manager on the host: the dissertation's swap_requested_pages
// (Garanzha 2014, §6.2; the steps are in page_cache.h) over a pool of slots
// filled by reads of the pack file.
//
// The costs per call are kept to sequential passes where possible: the
// requests are found by one pass over the descriptors that skips blocks of
// 64 unrequested pages with one OR; the TimeUsed reset and the WasRead
// marks touch only the cached pages (a missing page's descriptor holds
// nothing but its OOC and Requested bits). The sort is needed only once the
// pool is full, and it is Garanzha 2014's stable sort by key done as the keys
// allow: the cached pages lie in the prefix of the page ids, so a counting
// sort over the 32 TimeUsed values orders them; the missing pages only
// split into requested (32) and not (64), a stable partition that tests a
// byte per page (requested_missing_, set in step 1) instead of scattered
// descriptors, a quarter of the bytes. Until the first eviction the
// missing pages are in page order, which the pass over the descriptors
// gives for free, so a filling cache never goes through the page ids.
// Nothing is allocated per call except a reader's scratch buffer per read
// task (compressed pages only) and on the error path. On the 2-core
// development machine, 4M pages with a full pool of 400K slots: about
// 1.5 ms per swap without misses, 8 ms with a hundred (the reads aside).
//
// The budget covers the pool and every array here (page_cache.h names the
// bytes per page and per slot), so memory_bytes() <= budget_bytes; the pool
// is not zero-filled, so its untouched pages are not resident either.
#include "ooc/page_cache.h"

#include <algorithm>
#include <atomic>
#include <thread>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <exception>
#include <mutex>
#include <span>

#include "core/parallel.h"
#include "ooc/reader_pool.h"
#include "ooc/uring_reader.h"
#include "core/assert.h"
#include "rayforge/core/error.h"

namespace rf::pack {

namespace {

constexpr uint32_t kNoPage = 0xFFFFFFFFu;
constexpr uint32_t kTimeResetPeriod = 10;  // swaps between TimeUsed resets (Garanzha 2014's example)
constexpr uint32_t kScanBlock = 64;        // descriptors tested at once for a request
constexpr uint32_t kPrefetchAhead = 16;    // page ids, in the sort's gather of TimeUsed

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

uint32_t time_used(uint32_t descriptor) { return (descriptor & kTimeMask) >> kTimeShift; }
uint32_t count_use(uint32_t descriptor) {
    return (descriptor & kTimeMask) == kTimeMask ? descriptor : descriptor + (1u << kTimeShift);
}

// Slots that fit beside the tables of page_count pages, at most one per page.
uint32_t slots_within_budget(const std::string& name, uint32_t page_count, size_t slot_bytes, size_t budget_bytes) {
    if (page_count == 0) return 0;
    const uint64_t table = uint64_t(page_count) * PageCache::kTableBytesPerPage;
    const uint64_t per_slot = uint64_t(slot_bytes) + PageCache::kBookkeepingBytesPerSlot;
    const uint64_t fit = budget_bytes > table ? (budget_bytes - table) / per_slot : 0;
    if (fit == 0)
        throw Error(name + ": a budget of " + std::to_string(budget_bytes) + " bytes holds no slot (the table of " +
                    std::to_string(page_count) + " pages takes " + std::to_string(table) + " bytes, a slot " +
                    std::to_string(per_slot) + ")");
    const uint64_t slots = std::min<uint64_t>(fit, page_count);
    if (slots > kMaxSlots)
        throw Error(name + ": a budget of " + std::to_string(budget_bytes) + " bytes makes " + std::to_string(slots) +
                    " slots of " + std::to_string(slot_bytes) + " bytes, more than the " + std::to_string(kMaxSlots) +
                    " a descriptor can address");
    return uint32_t(slots);
}

void check_pages(const PackFile& file, const std::string& name, uint64_t first_page, uint32_t page_count,
                 size_t slot_bytes) {
    if (slot_bytes == 0) throw Error(name + ": slots of 0 bytes");
    const std::span<const PageEntry> directory = file.directory();
    if (first_page > directory.size() || page_count > directory.size() - first_page)
        throw Error(name + ": pages " + std::to_string(first_page) + " + " + std::to_string(page_count) +
                    " are not in the " + std::to_string(directory.size()) + " pages of " + file.path());
    for (uint32_t page = 0; page < page_count; ++page) {
        const PageEntry& entry = directory[first_page + page];
        if (entry.raw_bytes > slot_bytes)
            throw Error(name + ": page " + std::to_string(first_page + page) + " of " + file.path() + " holds " +
                        std::to_string(entry.raw_bytes) + " bytes, more than a slot's " + std::to_string(slot_bytes));
    }
}

}  // namespace

size_t largest_raw_page(const PackFile& file, uint64_t first, uint64_t count) {
    uint64_t largest = 1;
    for (uint64_t i = first; i < first + count; ++i) largest = std::max<uint64_t>(largest, file.directory()[i].raw_bytes);
    return size_t((largest + 15) & ~uint64_t(15));  // slots 16-byte aligned: page nodes are read in place
}

PageCache::PageCache(const PackFile& file, uint64_t first_page, uint32_t page_count, size_t slot_bytes,
                     size_t budget_bytes, std::string name)
    : file_(file), first_page_(first_page), name_(std::move(name)) {
    static_assert(kBookkeepingBytesPerSlot == 3 * sizeof(uint32_t) + sizeof(Admission) + sizeof(uint8_t));
    static_assert(kTableBytesPerPage == 3 * sizeof(uint32_t) + sizeof(uint8_t));
    check_pages(file, name_, first_page, page_count, slot_bytes);
    slot_count_ = slots_within_budget(name_, page_count, slot_bytes, budget_bytes);
    // Default-initialised: the pool's pages become resident as slots fill.
    if (slot_count_ > 0) pool_.reset(new uint8_t[size_t(slot_count_) * slot_bytes]);
    descriptors_.assign(page_count, kOutOfCore);
    page_ids_.resize(page_count);
    sorted_ids_.resize(page_count);
    requested_missing_.assign(page_count, 0);
    prefix_keys_.resize(slot_count_);
    slot_page_.assign(slot_count_, kNoPage);
    free_slots_.reserve(slot_count_);
    for (uint32_t slot = slot_count_; slot-- > 0;) free_slots_.push_back(slot);
    admissions_.reserve(slot_count_);
    last_loaded_.reserve(slot_count_);
    view_ = PageTableView{descriptors_.data(), pool_.get(), uint64_t(slot_bytes), page_count};
}

PageCache::~PageCache() = default;

size_t PageCache::memory_bytes() const {
    return size_t(slot_count_) * slot_bytes() +
           sizeof(uint32_t) * (descriptors_.capacity() + page_ids_.capacity() + sorted_ids_.capacity() +
                               free_slots_.capacity() + slot_page_.capacity() + last_loaded_.capacity()) +
           requested_missing_.capacity() + sizeof(Admission) * admissions_.capacity() +
           prefix_keys_.capacity();
}

size_t PageCache::swap_requested_pages() {
    const Clock::time_point start = Clock::now();
    const double io_before = stats_.io_ms;
    ++stats_.swaps;
    if (++calls_ % kTimeResetPeriod == 0) {
        for (uint32_t page : slot_page_)
            if (page != kNoPage) descriptors_[page] &= ~kTimeMask;
    }
    const uint32_t missing = count_requests();
    size_t loaded = 0;
    std::string error;
    last_loaded_.clear();
    if (missing > 0) {
        if (missing <= free_slots_.size())
            admit_to_free_slots(missing);
        else
            admit_least_used_out(missing);
        error = read_admissions();
        loaded = settle_admissions();
    }
    stats_.manage_ms += ms_since(start) - (stats_.io_ms - io_before);
    if (!error.empty()) throw Error(error);
    return loaded;
}

// Step 1: the stats, TimeUsed of the cached pages used (their Requested bit
// cleared), and the number of requested missing pages, whose Requested bit
// stays until they are admitted or deferred; they are also marked in
// requested_missing_, which the passes over the page ids test instead of
// the descriptors. While the missing pages are in page order and may all
// fit in the free slots, they are collected here, in that order.
uint32_t PageCache::count_requests() {
    uint32_t* descriptors = descriptors_.data();
    const uint32_t page_count = view_.page_count;
    const bool collect = tail_in_page_order_;
    const size_t free_slots = free_slots_.size();
    admissions_.clear();
    uint64_t requests = 0;
    uint32_t missing = 0;
    for (uint64_t block = 0; block < page_count; block += kScanBlock) {
        const uint32_t end = uint32_t(std::min<uint64_t>(page_count, block + kScanBlock));
        uint32_t any = 0;
        for (uint32_t page = uint32_t(block); page < end; ++page) any |= descriptors[page];
        if (!(any & kRequested)) continue;
        for (uint32_t page = uint32_t(block); page < end; ++page) {
            const uint32_t d = descriptors[page];
            if (!(d & kRequested)) continue;
            ++requests;
            if (d & kOutOfCore) {
                if (collect && missing < free_slots) admissions_.push_back({page, 0, false});
                requested_missing_[page] = 1;
                ++missing;
            } else {
                descriptors[page] = count_use(d) & ~kRequested;
            }
        }
    }
    stats_.requests += requests;
    stats_.misses += missing;
    stats_.hits += requests - missing;
    return missing;
}

// Step 2 while the cache fills up: every requested page gets a free slot and
// goes to the front of the cached prefix, in the order of the missing pages.
void PageCache::admit_to_free_slots(uint32_t missing) {
    const uint32_t cached = cached_count_;
    if (!tail_in_page_order_) {
        // Take the requested pages out of the tail, keeping both orders.
        admissions_.resize(missing);
        uint32_t next_admission = missing;
        uint32_t write = view_.page_count;
        for (uint32_t i = view_.page_count; i-- > cached;) {
            const uint32_t page = page_ids_[i];
            if (take_requested_missing(page))
                admissions_[--next_admission] = {page, 0, false};
            else
                page_ids_[--write] = page;
        }
        RF_ASSERT(next_admission == 0 && write == cached + missing, "the tail holds every requested missing page");
    }
    RF_ASSERT(admissions_.size() == missing, "every requested page collected");
    std::copy_backward(page_ids_.begin(), page_ids_.begin() + cached, page_ids_.begin() + cached + missing);
    for (uint32_t i = 0; i < missing; ++i) {
        Admission& a = admissions_[i];
        requested_missing_[a.page] = 0;
        a.slot = free_slots_.back();
        free_slots_.pop_back();
        page_ids_[i] = a.page;
    }
}

// Step 2 with a full pool (or too few free slots): Garanzha 2014's LFU swap.
// After the sort, page_ids_ is [cached by TimeUsed | requested | the rest];
// the first `admitted` requested pages take the free slots and the slots of
// the `evicted` least used cached pages, the others are deferred, and the
// prefix becomes [admitted | cached that stay | evicted].
void PageCache::admit_least_used_out(uint32_t missing) {
    const uint32_t cached = cached_count_;
    const uint32_t free_slots = uint32_t(free_slots_.size());
    sort_by_lfu_key(missing);
    const uint32_t admitted = std::min(missing, slot_count_);
    const uint32_t evicted = admitted - free_slots;  // missing > free_slots, so admitted >= free_slots
    RF_ASSERT(admitted >= free_slots && evicted <= cached, "the pool holds the cached pages and the free slots");
    admissions_.resize(admitted);
    for (uint32_t i = 0; i < admitted; ++i) {
        Admission& a = admissions_[i];
        a = {page_ids_[cached + i], 0, false};
        if (i < evicted) {
            a.slot = descriptors_[page_ids_[i]] & kSlotMask;  // Garanzha 2014's pairwise swap
            evict(page_ids_[i]);
        } else {
            a.slot = free_slots_.back();
            free_slots_.pop_back();
        }
    }
    for (uint32_t i = cached + admitted; i < cached + missing; ++i) descriptors_[page_ids_[i]] &= ~kRequested;
    // [evicted | stay | admitted] -> [admitted | stay | evicted]
    const auto prefix = page_ids_.begin();
    std::reverse(prefix, prefix + cached + admitted);
    std::reverse(prefix, prefix + admitted);
    std::reverse(prefix + admitted, prefix + cached + admitted - evicted);
    std::reverse(prefix + cached + admitted - evicted, prefix + cached + admitted);
}

// A stable sort of the page ids by the LFU key into sorted_ids_, swapped
// into page_ids_: the cached prefix by TimeUsed (0-31), then the missing
// pages, requested (32) before the others (64).
void PageCache::sort_by_lfu_key(uint32_t missing) {
    const uint32_t cached = cached_count_;
    uint32_t start[kTimeMax + 2] = {};
    for (uint32_t i = 0; i < cached; ++i) {
        // Scattered loads, the sort's main cost on large tables: ask ahead.
        if (i + kPrefetchAhead < cached) __builtin_prefetch(&descriptors_[page_ids_[i + kPrefetchAhead]]);
        prefix_keys_[i] = uint8_t(time_used(descriptors_[page_ids_[i]]));
        ++start[prefix_keys_[i] + 1];
    }
    for (uint32_t key = 1; key <= kTimeMax + 1; ++key) start[key] += start[key - 1];
    for (uint32_t i = 0; i < cached; ++i) sorted_ids_[start[prefix_keys_[i]]++] = page_ids_[i];
    uint32_t requested = cached;
    uint32_t other = cached + missing;
    if (tail_in_page_order_) {
        for (uint32_t page = 0; page < view_.page_count; ++page) {
            const uint32_t d = descriptors_[page];
            if (!(d & kOutOfCore)) continue;
            if (d & kRequested) {
                requested_missing_[page] = 0;
                sorted_ids_[requested++] = page;
            } else {
                sorted_ids_[other++] = page;
            }
        }
        tail_in_page_order_ = false;  // the evictions to come break page order
    } else {
        for (uint32_t i = cached; i < view_.page_count; ++i) {
            const uint32_t page = page_ids_[i];
            sorted_ids_[take_requested_missing(page) ? requested++ : other++] = page;
        }
    }
    RF_ASSERT(requested == cached + missing && other == view_.page_count, "the keys count every page once");
    page_ids_.swap(sorted_ids_);
}

bool PageCache::take_requested_missing(uint32_t page) {
    if (!requested_missing_[page]) return false;
    requested_missing_[page] = 0;
    return true;
}

// An evicted page keeps WasRead: it was searched by every ray of the query
// loop, so no ray asks for it again in this loop (without that, a pool
// smaller than a loop's pages would evict and reload the same pages forever).
void PageCache::evict(uint32_t page) {
    slot_page_[descriptors_[page] & kSlotMask] = kNoPage;
    descriptors_[page] = kOutOfCore | (descriptors_[page] & kWasRead);
    evicted_read_ = evicted_read_ || (descriptors_[page] & kWasRead) != 0;
    --cached_count_;
    ++stats_.evictions;
}

// Step 3: reads every admission into its slot with a real queue depth. With
// io_uring (uring_reader.h) one thread keeps the stored bytes of all of
// them in flight while the reader pool checks and decodes each page as its
// read completes; otherwise each pool thread (reader_pool.h) reads, checks
// and decodes one page at a time. Returns the first failure's message by
// admission order ("" when all were read).
std::string PageCache::read_admissions() {
    const Clock::time_point start = Clock::now();
    std::mutex error_mutex;
    size_t error_index = admissions_.size();
    std::string error;
    const auto fail = [&](size_t i, const std::string& what) {
        const std::lock_guard<std::mutex> lock(error_mutex);
        if (i < error_index) {
            error_index = i;
            error = name_ + ": " + what;  // the reader's message names the file, page and offset
        }
    };
    std::atomic<uint64_t> bytes_read{0};
    UringReader* uring = admissions_.empty() ? nullptr : UringReader::shared();
    std::vector<UringReader::Read> reads = uring ? uring_reads() : std::vector<UringReader::Read>{};
    // ready[i]: read i is done (its reader waits on that flag alone).
    std::vector<std::atomic<uint8_t>> ready(reads.size());
    std::thread io;
    if (uring)
        io = std::thread([&] {
            uring->read_all(reads, [&](size_t i) {
                ready[i].store(1, std::memory_order_release);
                ready[i].notify_one();
            });
        });
    ReaderPool::shared().run(admissions_.size(), [&](size_t i) {
        thread_local std::vector<uint8_t> scratch;  // a compressed page's stored bytes, one per reader
        Admission& a = admissions_[i];
        const std::span<uint8_t> slot(pool_.get() + uint64_t(a.slot) * view_.slot_bytes, view_.slot_bytes);
        const uint64_t page = first_page_ + a.page;
        try {  // a reader must not throw
            if (!uring) {
                bytes_read += file_.read_page(page, slot, scratch);
                a.ok = true;
                return;
            }
            ready[i].wait(0, std::memory_order_acquire);
            const int read_error = read_errors_[i] != 0 ? read_errors_[i] : reads[i].error;
            const PageEntry& e = file_.entry(page);
            if (read_error != 0)
                throw Error(file_.path() + ": byte " + std::to_string(e.offset) + ": cannot read page " +
                            std::to_string(page) + ": " + std::strerror(read_error));
            const std::span<const uint8_t> stored =
                e.codec == Codec::None ? std::span<const uint8_t>(slot.data(), e.stored_bytes) : stored_[i];
            file_.finish_page(page, stored, slot);
            bytes_read += e.stored_bytes;
            a.ok = true;
        } catch (const std::exception& e) {
            fail(i, e.what());
        }
    });
    if (io.joinable()) io.join();
    stats_.bytes_read += bytes_read;
    stats_.io_ms += ms_since(start);
    return error;
}

// io_uring's reads of the admissions' stored bytes: a raw page straight into
// its slot, a compressed one into stored_[i]; read_errors_[i] set for a read
// not made.
std::vector<UringReader::Read> PageCache::uring_reads() {
    std::vector<UringReader::Read> reads(admissions_.size());
    if (stored_.size() < admissions_.size()) stored_.resize(admissions_.size());
    read_errors_.assign(admissions_.size(), 0);
    for (size_t i = 0; i < admissions_.size(); ++i) {
        const PageEntry& e = file_.entry(first_page_ + admissions_[i].page);
        uint8_t* into = pool_.get() + uint64_t(admissions_[i].slot) * view_.slot_bytes;
        if (e.codec != Codec::None) {
            stored_[i].resize(e.stored_bytes);
            into = stored_[i].data();
        } else if (e.stored_bytes > view_.slot_bytes) {
            read_errors_[i] = EFBIG;  // (the checks at open make this impossible)
            continue;
        }
        reads[i] = {file_.fd(), e.offset, e.stored_bytes, into, 0};
    }
    return reads;
}

// The descriptors of this call's admissions: a page read is cached with
// TimeUsed 0 and no flags; one that failed stays out and frees its slot.
size_t PageCache::settle_admissions() {
    const uint32_t prefix = cached_count_ + uint32_t(admissions_.size());
    size_t loaded = 0;
    for (const Admission& a : admissions_) {
        if (a.ok) {
            descriptors_[a.page] = a.slot;
            slot_page_[a.slot] = a.page;
            last_loaded_.push_back(a.page);
            ++loaded;
        } else {
            descriptors_[a.page] = kOutOfCore;
            free_slots_.push_back(a.slot);
        }
    }
    cached_count_ += uint32_t(loaded);
    stats_.pages_read += loaded;
    if (loaded < admissions_.size()) move_failed_to_missing(prefix);
    return loaded;
}

// The pages that failed to read leave the cached prefix of the page ids for
// the front of the missing ones (both orders kept). That ends page order
// among the missing pages, so a tail not kept until now is written out:
// the failed pages, then the other missing pages in page order. An error
// path: it may allocate.
void PageCache::move_failed_to_missing(uint32_t prefix) {
    const auto is_cached = [&](uint32_t page) { return !(descriptors_[page] & kOutOfCore); };
    std::stable_partition(page_ids_.begin(), page_ids_.begin() + prefix, is_cached);
    if (!tail_in_page_order_) return;
    std::vector<uint32_t> failed(page_ids_.begin() + cached_count_, page_ids_.begin() + prefix);
    std::sort(failed.begin(), failed.end());
    uint32_t write = prefix;
    for (uint32_t page = 0; page < view_.page_count; ++page)
        if (!is_cached(page) && !std::binary_search(failed.begin(), failed.end(), page)) page_ids_[write++] = page;
    RF_ASSERT(write == view_.page_count, "every page has one place in the page ids");
    tail_in_page_order_ = false;
}

void PageCache::mark_cached_as_read() {
    for (uint32_t page : slot_page_)
        if (page != kNoPage) descriptors_[page] |= kWasRead;
}

void PageCache::clear_was_read() {
    if (evicted_read_) {  // missing pages may hold it too
        for (uint32_t& d : descriptors_) d &= ~kWasRead;
        evicted_read_ = false;
        return;
    }
    for (uint32_t page : slot_page_)
        if (page != kNoPage) descriptors_[page] &= ~kWasRead;
}

void PageCache::clear() {
    std::fill(descriptors_.begin(), descriptors_.end(), kOutOfCore);
    std::fill(slot_page_.begin(), slot_page_.end(), kNoPage);
    free_slots_.clear();
    for (uint32_t slot = slot_count_; slot-- > 0;) free_slots_.push_back(slot);
    cached_count_ = 0;
    calls_ = 0;
    tail_in_page_order_ = true;
}

}  // namespace rf::pack
