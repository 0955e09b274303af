// The page manager (ooc/page_cache.h) on small hand-written pack files:
// pages come back byte-exact; the budget bounds the slots and the memory,
// and the pool is resident only as it fills; the LFU swap of Garanzha 2014
// (Garanzha 2014, §6.2) evicts what hand-computed sequences say, including
// its stable order among equal keys and the TimeUsed reset every 10th swap;
// requests beyond the pool are served by later swaps; WasRead, the
// statistics and corrupted pages; and, on random workloads (requested from
// many threads in one test), descriptor-for-descriptor equality with a
// plain serial model of the same algorithm (all page ids kept in order, a
// full stable sort on every swap that needs one).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstring>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "core/parallel.h"
#include "ooc/pack_file.h"
#include "ooc/pack_format.h"
#include "ooc/page_cache.h"
#include "ooc/reader_pool.h"
#include "ooc/uring_reader.h"
#include "rayforge/core/error.h"
#include "test_paths.h"

#include <fcntl.h>
#include <unistd.h>

namespace rf::pack {
namespace {

// ---------------------------------------------------------------- test files

struct TestPage {
    std::vector<uint8_t> raw;
    bool zstd = false;  // stored as a zstd frame (of one raw block), to go through the reader's scratch buffer
};

// A zstd frame holding `raw` as one uncompressed block (RFC 8878, §3.1.1):
// the reader's decompression path without linking zstd into the tests.
std::vector<uint8_t> zstd_raw_frame(const std::vector<uint8_t>& raw) {
    std::vector<uint8_t> out = {0x28, 0xB5, 0x2F, 0xFD, 0xA0};  // magic; single segment, 4-byte content size
    const uint32_t size = uint32_t(raw.size());
    for (int b = 0; b < 4; ++b) out.push_back(uint8_t(size >> (8 * b)));
    const uint32_t block = 1u | (size << 3);  // last block, type raw
    for (int b = 0; b < 3; ++b) out.push_back(uint8_t(block >> (8 * b)));
    out.insert(out.end(), raw.begin(), raw.end());
    return out;
}

std::vector<uint8_t> stored_bytes(const TestPage& page) { return page.zstd ? zstd_raw_frame(page.raw) : page.raw; }

template <class T>
void append(std::vector<uint8_t>& out, const T& value) {
    const size_t at = out.size();
    out.resize(at + sizeof(T));
    std::memcpy(out.data() + at, &value, sizeof(T));
}

void pad16(std::vector<uint8_t>& out) { out.resize((out.size() + 15) & ~size_t(15), 0); }

// A valid pack of attribute pages only: header | pages | directory |
// resident section (its header, the one cell of a 1^3 grid, empty, one
// material). Attribute pages that no geometry page owns are not size-checked. Returns
// each page's offset in the file.
std::vector<uint64_t> write_test_pack(const std::string& path, const std::vector<TestPage>& pages) {
    std::vector<uint8_t> file(sizeof(FileHeader), 0);
    std::vector<PageEntry> directory;
    std::vector<uint64_t> offsets;
    for (const TestPage& page : pages) {
        const std::vector<uint8_t> stored = stored_bytes(page);
        PageEntry e;
        e.offset = file.size();
        e.stored_bytes = uint32_t(stored.size());
        e.raw_bytes = uint32_t(page.raw.size());
        e.checksum = crc32c(stored.data(), stored.size());
        e.kind = PageKind::Attributes;
        e.codec = page.zstd ? Codec::Zstd : Codec::None;
        directory.push_back(e);
        offsets.push_back(e.offset);
        file.insert(file.end(), stored.begin(), stored.end());
    }
    pad16(file);
    FileHeader h;
    std::memcpy(h.magic, kMagic, sizeof(kMagic));
    h.directory_offset = file.size();
    h.page_count = pages.size();
    h.attribute_pages = uint32_t(pages.size());
    for (const PageEntry& e : directory) append(file, e);
    h.directory_checksum = crc32c(directory.data(), directory.size() * sizeof(PageEntry));
    pad16(file);

    std::vector<uint8_t> resident;
    ResidentHeader r;
    r.material_count = 1;  // a file has at least one material
    append(resident, r);
    pad16(resident);
    append(resident, kEmptyCell);
    pad16(resident);
    append(resident, ShadingMaterial{});
    pad16(resident);
    h.resident_offset = file.size();
    h.resident_bytes = resident.size();
    h.resident_checksum = crc32c(resident.data(), resident.size());
    file.insert(file.end(), resident.begin(), resident.end());

    h.file_bytes = file.size();
    h.header_checksum = crc32c(&h, offsetof(FileHeader, header_checksum));
    std::memcpy(file.data(), &h, sizeof(h));
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(file.data()), std::streamsize(file.size()));
    return offsets;
}

// `count` pages of random bytes, sizes in [min_bytes, max_bytes], every third one zstd-framed.
std::vector<TestPage> random_pages(uint32_t count, uint32_t min_bytes, uint32_t max_bytes, uint32_t seed) {
    std::mt19937 rng(seed);
    std::vector<TestPage> pages(count);
    for (uint32_t i = 0; i < count; ++i) {
        pages[i].raw.resize(std::uniform_int_distribution<uint32_t>(min_bytes, max_bytes)(rng));
        for (uint8_t& b : pages[i].raw) b = uint8_t(rng());
        pages[i].zstd = i % 3 == 1;
    }
    return pages;
}

// The budget that gives exactly `slots` slots (and a little to spare).
size_t budget_for(uint32_t pages, uint32_t slots, size_t slot_bytes) {
    return size_t(pages) * PageCache::kTableBytesPerPage +
           size_t(slots) * (slot_bytes + PageCache::kBookkeepingBytesPerSlot) + slot_bytes / 2;
}

// A pack file written into a fresh directory, and its pages.
struct Fixture {
    Fixture(const std::string& name, std::vector<TestPage> p)
        : path(test::temp_dir("page_cache_" + name) + "/test.rfpack"), pages(std::move(p)) {
        offsets = write_test_pack(path, pages);
    }
    std::string path;
    std::vector<TestPage> pages;
    std::vector<uint64_t> offsets;
};

// ------------------------------------------------------------------ checks

uint32_t time_used(uint32_t d) { return (d & kTimeMask) >> kTimeShift; }
bool is_cached(PageCache& cache, uint32_t page) { return !(cache.view().descriptor(page) & kOutOfCore); }

std::set<uint32_t> cached_set(PageCache& cache) {
    std::set<uint32_t> s;
    for (uint32_t p = 0; p < cache.page_count(); ++p)
        if (is_cached(cache, p)) s.insert(p);
    return s;
}

void request(PageCache& cache, std::initializer_list<uint32_t> pages) {
    for (uint32_t p : pages) cache.view().request(p);
}

// The invariants after every swap: the cached pages hold their bytes in
// distinct slots, their count is cached_count() <= slot_count(), missing
// descriptors are kOutOfCore (with WasRead when evicted after a search), no
// Requested bit is left.
void expect_consistent(PageCache& cache, const std::vector<TestPage>& pages, uint32_t first_page = 0) {
    const PageTableView view = cache.view();
    std::set<uint32_t> slots;
    uint32_t cached = 0;
    for (uint32_t p = 0; p < cache.page_count(); ++p) {
        const uint32_t d = view.descriptor(p);
        EXPECT_FALSE(d & kRequested) << "page " << p;
        if (d & kOutOfCore) {
            EXPECT_EQ(d & ~kWasRead, kOutOfCore) << "page " << p;
            EXPECT_EQ(view.cached(p), nullptr);
            continue;
        }
        ++cached;
        EXPECT_LT(d & kSlotMask, cache.slot_count()) << "page " << p;
        EXPECT_TRUE(slots.insert(d & kSlotMask).second) << "slot shared, page " << p;
        const std::vector<uint8_t>& raw = pages[first_page + p].raw;
        EXPECT_EQ(std::memcmp(view.cached(p), raw.data(), raw.size()), 0) << "bytes of page " << p;
    }
    EXPECT_EQ(cached, cache.cached_count());
    EXPECT_LE(cached, cache.slot_count());
}

template <class F>
std::string error_of(F&& f) {
    try {
        f();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

// ------------------------------------------------------------ serial model

// The algorithm of page_cache.h written the plain way: all page ids kept in
// order at all times, std::stable_sort by the LFU key whenever the free slots
// do not suffice; the pages in `bad` fail to read. The manager must match it
// descriptor for descriptor.
class Model {
public:
    Model(uint32_t pages, uint32_t slots, std::set<uint32_t> bad = {})
        : slots_(slots), bad_(std::move(bad)), desc_(pages, kOutOfCore), ids_(pages) {
        for (uint32_t p = 0; p < pages; ++p) ids_[p] = p;
        for (uint32_t s = slots; s-- > 0;) free_.push_back(s);
    }
    void request(uint32_t page) { desc_[page] |= kRequested; }
    uint32_t descriptor(uint32_t page) const { return desc_[page]; }
    PageCacheStats stats;
    bool failed = false;  // the last swap read a bad page

    size_t swap() {
        failed = false;
        ++stats.swaps;
        if (++calls_ % 10 == 0)
            for (uint32_t& d : desc_) d &= ~kTimeMask;
        uint32_t missing = 0;
        for (uint32_t& d : desc_) {
            if (!(d & kRequested)) continue;
            ++stats.requests;
            if (d & kOutOfCore) {
                ++missing;
                continue;
            }
            ++stats.hits;
            if (time_used(d) < kTimeMax) d += 1u << kTimeShift;
            d &= ~kRequested;
        }
        stats.misses += missing;
        if (missing == 0) return 0;
        uint32_t cached = uint32_t(desc_.size()) - count_missing();
        std::vector<uint32_t> admitted, slots;
        if (missing <= free_.size()) {
            std::vector<uint32_t> rest;
            for (uint32_t i = cached; i < ids_.size(); ++i)
                (desc_[ids_[i]] & kRequested ? admitted : rest).push_back(ids_[i]);
            std::vector<uint32_t> ids = admitted;
            ids.insert(ids.end(), ids_.begin(), ids_.begin() + cached);
            ids.insert(ids.end(), rest.begin(), rest.end());
            ids_ = ids;
            for (size_t i = 0; i < admitted.size(); ++i) slots.push_back(pop_free());
        } else {
            auto key = [&](uint32_t p) {
                const uint32_t d = desc_[p];
                return (d & kOutOfCore) ? ((d & kRequested) ? 32u : 64u) : time_used(d);
            };
            std::stable_sort(ids_.begin(), ids_.end(), [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
            const uint32_t count = std::min<uint32_t>(missing, slots_);
            const uint32_t evicted = count - uint32_t(free_.size());
            admitted.assign(ids_.begin() + cached, ids_.begin() + cached + count);
            for (uint32_t i = cached + count; i < cached + missing; ++i) desc_[ids_[i]] &= ~kRequested;
            for (uint32_t i = 0; i < count; ++i) {
                if (i < evicted) {
                    slots.push_back(desc_[ids_[i]] & kSlotMask);
                    desc_[ids_[i]] = kOutOfCore | (desc_[ids_[i]] & kWasRead);  // a searched page stays searched
                    ++stats.evictions;
                } else {
                    slots.push_back(pop_free());
                }
            }
            std::vector<uint32_t> ids = admitted;
            ids.insert(ids.end(), ids_.begin() + evicted, ids_.begin() + cached);
            ids.insert(ids.end(), ids_.begin(), ids_.begin() + evicted);
            ids.insert(ids.end(), ids_.begin() + cached + count, ids_.end());
            ids_ = ids;
            cached -= evicted;
        }
        size_t loaded = 0;
        for (size_t i = 0; i < admitted.size(); ++i) {
            if (bad_.count(admitted[i])) {
                desc_[admitted[i]] = kOutOfCore;
                free_.push_back(slots[i]);
                failed = true;
            } else {
                desc_[admitted[i]] = slots[i];
                ++loaded;
            }
        }
        // A page that failed leaves the cached prefix, both orders kept.
        std::stable_partition(ids_.begin(), ids_.begin() + cached + admitted.size(),
                              [&](uint32_t p) { return !(desc_[p] & kOutOfCore); });
        stats.pages_read += loaded;
        return loaded;
    }
    void mark_cached_as_read() {
        for (uint32_t& d : desc_)
            if (!(d & kOutOfCore)) d |= kWasRead;
    }
    void clear_was_read() {
        for (uint32_t& d : desc_) d &= ~kWasRead;
    }

private:
    uint32_t count_missing() const {
        return uint32_t(std::count_if(desc_.begin(), desc_.end(), [](uint32_t d) { return (d & kOutOfCore) != 0; }));
    }
    uint32_t pop_free() {
        const uint32_t s = free_.back();
        free_.pop_back();
        return s;
    }

    uint32_t slots_;
    std::set<uint32_t> bad_;
    uint32_t calls_ = 0;
    std::vector<uint32_t> desc_;
    std::vector<uint32_t> ids_;
    std::vector<uint32_t> free_;
};

void expect_matches(PageCache& cache, const Model& model, const std::string& where) {
    for (uint32_t p = 0; p < cache.page_count(); ++p)
        ASSERT_EQ(cache.view().descriptor(p), model.descriptor(p)) << where << ", page " << p;
    const PageCacheStats& a = cache.stats();
    const PageCacheStats& b = model.stats;
    EXPECT_EQ(a.requests, b.requests) << where;
    EXPECT_EQ(a.hits, b.hits) << where;
    EXPECT_EQ(a.misses, b.misses) << where;
    EXPECT_EQ(a.pages_read, b.pages_read) << where;
    EXPECT_EQ(a.evictions, b.evictions) << where;
    EXPECT_EQ(a.swaps, b.swaps) << where;
}

// ------------------------------------------------------------------- tests

TEST(PageCache, PagesComeBackByteExact) {
    Fixture f("exact", random_pages(40, 1, 700, 1));
    PackFile file(f.path);
    PageCache cache(file, 0, 40, 700, budget_for(40, 40, 700), "attributes");
    EXPECT_EQ(cache.slot_count(), 40u);
    for (uint32_t p = 0; p < 40; ++p) {
        EXPECT_EQ(cache.view().cached(p), nullptr);
        cache.view().request(p);
    }
    EXPECT_EQ(cache.swap_requested_pages(), 40u);
    expect_consistent(cache, f.pages);
    EXPECT_EQ(cache.cached_count(), 40u);
    // Nothing requested: nothing happens.
    EXPECT_EQ(cache.swap_requested_pages(), 0u);
    expect_consistent(cache, f.pages);
}

TEST(PageCache, ASubrangeOfTheDirectory) {
    Fixture f("subrange", random_pages(30, 64, 64, 2));
    PackFile file(f.path);
    PageCache cache(file, 10, 12, 64, budget_for(12, 5, 64), "tiles");
    EXPECT_EQ(cache.page_count(), 12u);
    request(cache, {0, 3, 11});
    EXPECT_EQ(cache.swap_requested_pages(), 3u);
    expect_consistent(cache, f.pages, 10);
}

TEST(PageCache, BudgetBoundsSlotsAndMemory) {
    Fixture f("budget", random_pages(64, 100, 256, 3));
    PackFile file(f.path);
    for (uint32_t slots : {1u, 2u, 7u, 63u, 64u}) {
        const size_t budget = budget_for(64, slots, 256);
        PageCache cache(file, 0, 64, 256, budget, "geometry");
        EXPECT_EQ(cache.slot_count(), slots);
        EXPECT_LE(cache.memory_bytes(), budget);
        // The budget is used: one more slot would not fit.
        EXPECT_GT(cache.memory_bytes() + 256 + PageCache::kBookkeepingBytesPerSlot, budget);
        std::mt19937 rng(slots);
        for (int swap = 0; swap < 40; ++swap) {
            const int n = int(rng() % 20);
            for (int i = 0; i < n; ++i) cache.view().request(rng() % 64);
            cache.swap_requested_pages();
            expect_consistent(cache, f.pages);
            EXPECT_LE(cache.cached_count(), slots);
            EXPECT_LE(cache.memory_bytes(), budget);
        }
    }
    // A budget far above the scene: one slot per page, no more.
    PageCache big(file, 0, 64, 256, size_t(1) << 30, "geometry");
    EXPECT_EQ(big.slot_count(), 64u);
}

// Resident bytes of this process (Linux), 0 where unknown.
size_t resident_bytes() {
    std::ifstream statm("/proc/self/statm");
    size_t pages = 0, resident = 0;
    if (!(statm >> pages >> resident)) return 0;
    return resident * size_t(sysconf(_SC_PAGESIZE));
}

// The pool is not zero-filled: a large budget costs memory only as slots fill.
TEST(PageCache, ThePoolBecomesResidentOnlyAsItFills) {
    Fixture f("resident", random_pages(64, 100, 4096, 19));
    PackFile file(f.path);
    const size_t slot_bytes = size_t(4) << 20;  // 64 slots of 4 MB: a 256 MB pool
    const size_t before = resident_bytes();
    if (before == 0) GTEST_SKIP() << "no /proc/self/statm";
    PageCache cache(file, 0, 64, slot_bytes, budget_for(64, 64, slot_bytes), "resident");
    ASSERT_EQ(cache.slot_count(), 64u);
    request(cache, {0, 1, 2, 3});
    cache.swap_requested_pages();
    expect_consistent(cache, f.pages);
    // 4 pages of at most 4 KB were written; allow for the allocator and
    // AddressSanitizer's shadow (an eighth of the pool).
    EXPECT_LT(resident_bytes(), before + (size_t(64) << 20)) << cache.memory_bytes() << " bytes budgeted";
}

TEST(PageCache, ConstructorErrorsNameTheManagerAndTheNumbers) {
    Fixture f("errors", random_pages(8, 100, 300, 4));
    PackFile file(f.path);
    std::string m = error_of([&] { PageCache c(file, 0, 8, 300, budget_for(8, 1, 300) - 300, "geometry cache"); });
    EXPECT_NE(m.find("geometry cache"), std::string::npos) << m;
    EXPECT_NE(m.find(std::to_string(budget_for(8, 1, 300) - 300)), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    m = error_of([&] { PageCache c(file, 0, 8, 99, size_t(1) << 20, "textures"); });
    EXPECT_NE(m.find("textures"), std::string::npos) << m;
    EXPECT_NE(m.find("than a slot's 99"), std::string::npos) << m;
    m = error_of([&] { PageCache c(file, 4, 5, 300, size_t(1) << 20, "attributes"); });
    EXPECT_NE(m.find("attributes"), std::string::npos) << m;
    m = error_of([&] { PageCache c(file, 0, 8, 0, size_t(1) << 20, "attributes"); });
    EXPECT_NE(m.find("attributes"), std::string::npos) << m;
    // No pages: no slots, nothing to do.
    PageCache empty(file, 8, 0, 300, 0, "none");
    EXPECT_EQ(empty.slot_count(), 0u);
    EXPECT_EQ(empty.swap_requested_pages(), 0u);
}

// Hand-computed: 3 slots, pages 0-5.
TEST(PageCache, LfuKeepsTheMostUsed) {
    Fixture f("lfu", random_pages(6, 32, 32, 5));
    PackFile file(f.path);
    PageCache cache(file, 0, 6, 32, budget_for(6, 3, 32), "lfu");
    ASSERT_EQ(cache.slot_count(), 3u);
    request(cache, {0, 1, 2});
    EXPECT_EQ(cache.swap_requested_pages(), 3u);  // free slots; ids [0 1 2]
    request(cache, {0, 1});
    EXPECT_EQ(cache.swap_requested_pages(), 0u);  // TimeUsed 0:1 1:1 2:0
    request(cache, {0});
    EXPECT_EQ(cache.swap_requested_pages(), 0u);  // 0:2 1:1 2:0
    request(cache, {1, 3});
    EXPECT_EQ(cache.swap_requested_pages(), 1u);  // 0:2 1:2 2:0: 2 goes; ids [3 | 0 1 | 2]
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{0, 1, 3}));
    EXPECT_EQ(time_used(cache.view().descriptor(0)), 2u);
    EXPECT_EQ(time_used(cache.view().descriptor(1)), 2u);
    EXPECT_EQ(time_used(cache.view().descriptor(3)), 0u);  // a new page starts at 0
    request(cache, {1});
    request(cache, {4, 5});
    // 3:0 0:2 1:3, sorted [3 0 1]: 3 and 0 go.
    EXPECT_EQ(cache.swap_requested_pages(), 2u);
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{1, 4, 5}));
    EXPECT_EQ(cache.stats().evictions, 3u);
    expect_consistent(cache, f.pages);
}

// Equal keys keep the previous order of the page ids, in which a swap puts
// the admitted pages first: with no use at all, the newest page goes first.
TEST(PageCache, EqualKeysKeepThePreviousOrder) {
    Fixture f("stable", random_pages(10, 16, 16, 6));
    PackFile file(f.path);
    PageCache cache(file, 0, 10, 16, budget_for(10, 4, 16), "stable");
    request(cache, {2, 3});
    cache.swap_requested_pages();  // ids [2 3]
    request(cache, {0, 1});
    cache.swap_requested_pages();  // ids [0 1 2 3]
    request(cache, {4});
    cache.swap_requested_pages();  // all keys 0: 0 goes; ids [4 1 2 3 | 0 5 6 7 8 9]
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{1, 2, 3, 4}));
    request(cache, {5});
    cache.swap_requested_pages();  // 4 goes; ids [5 1 2 3 | 4 0 6 7 8 9]
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{1, 2, 3, 5}));
    request(cache, {5});
    request(cache, {7, 6});
    cache.swap_requested_pages();  // 1:0 2:0 3:0 5:1, sorted [1 2 3 5]: 1 and 2 go; ids [6 7 3 5 | 1 2 4 0 8 9]
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{3, 5, 6, 7}));
    // More requests than slots: they are admitted in the order of the ids,
    // the pages evicted last first, the ones never loaded last.
    request(cache, {9, 0, 2, 8, 1, 4});
    EXPECT_EQ(cache.swap_requested_pages(), 4u);  // all four go (6 7 3 at 0, 5 at 1); 1 2 4 0 come in
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{0, 1, 2, 4}));
    request(cache, {9, 8});
    EXPECT_EQ(cache.swap_requested_pages(), 2u);
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{0, 4, 8, 9}));  // ids [1 2 4 0 | ...], all at 0: 1 and 2 go
    expect_consistent(cache, f.pages);
}

// The TimeUsed reset on the 10th swap comes before that swap's counting.
TEST(PageCache, TimeUsedIsResetEveryTenthSwap) {
    Fixture f("reset", random_pages(5, 16, 16, 7));
    PackFile file(f.path);
    PageCache cache(file, 0, 5, 16, budget_for(5, 3, 16), "reset");
    request(cache, {0, 1, 2});
    cache.swap_requested_pages();  // swap 1
    for (int swap = 2; swap <= 9; ++swap) {
        request(cache, {0});
        if (swap == 2) request(cache, {2});
        cache.swap_requested_pages();
    }
    EXPECT_EQ(time_used(cache.view().descriptor(0)), 8u);
    EXPECT_EQ(time_used(cache.view().descriptor(2)), 1u);
    // Swap 10: reset, then 1 counts 1; 0 and 2 are at 0 and 0 is first in the ids.
    request(cache, {1, 3});
    EXPECT_EQ(cache.swap_requested_pages(), 1u);
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{1, 2, 3}));
    EXPECT_EQ(time_used(cache.view().descriptor(1)), 1u);
    EXPECT_EQ(time_used(cache.view().descriptor(2)), 0u);
    // Counting saturates at 31, and swap 20 resets again.
    for (int swap = 11; swap <= 19; ++swap) {
        request(cache, {2});
        cache.swap_requested_pages();
    }
    EXPECT_EQ(time_used(cache.view().descriptor(2)), 9u);
    cache.swap_requested_pages();  // swap 20
    EXPECT_EQ(time_used(cache.view().descriptor(1)), 0u);
    EXPECT_EQ(time_used(cache.view().descriptor(2)), 0u);
    // Used on every swap: 9 by swap 29 (21-29), then 10 by swap 39 (30-39).
    for (int swap = 21; swap <= 39; ++swap) {
        request(cache, {3});
        cache.swap_requested_pages();
        if (swap == 29) {
            EXPECT_EQ(time_used(cache.view().descriptor(3)), 9u);
        }
    }
    EXPECT_EQ(time_used(cache.view().descriptor(3)), 10u);
    // The reset count starts again after clear().
    cache.clear();
    request(cache, {4});
    cache.swap_requested_pages();
    for (int swap = 2; swap <= 9; ++swap) {
        request(cache, {4});
        cache.swap_requested_pages();
    }
    EXPECT_EQ(time_used(cache.view().descriptor(4)), 8u);
}

TEST(PageCache, TimeUsedSaturatesAt31) {
    Fixture f("saturate", random_pages(2, 16, 16, 8));
    PackFile file(f.path);
    PageCache cache(file, 0, 2, 16, budget_for(2, 2, 16), "saturate");
    // Without the reset (it comes every 10th swap) a count cannot pass 9, so
    // look at the step itself: 31 stays 31 through one more use.
    request(cache, {0});
    cache.swap_requested_pages();
    for (int i = 0; i < 7; ++i) {
        request(cache, {0});
        cache.swap_requested_pages();
    }
    EXPECT_EQ(time_used(cache.view().descriptor(0)), 7u);
    uint32_t* d = cache.view().descriptors;
    *d |= kTimeMask;  // as if counted to 31
    request(cache, {0});
    cache.swap_requested_pages();  // swap 9
    EXPECT_EQ(time_used(cache.view().descriptor(0)), 31u);
    EXPECT_EQ(cache.view().descriptor(0) & kSlotMask, 0u);
    EXPECT_FALSE(cache.view().descriptor(0) & kWasRead);
}

// Requests beyond the pool are deferred: rays that need a set of pages keep
// asking for those they have not seen; each swap loads min(k, outstanding)
// of them, in page order (the missing pages' order until evictions reorder
// it, and evicted pages are not asked for again here), so page p is first
// seen in iteration p / k + 2.
TEST(PageCache, DeferredRequestsAreServedByLaterSwaps) {
    const uint32_t n = 50;
    Fixture f("deferred", random_pages(n, 40, 40, 9));
    PackFile file(f.path);
    for (uint32_t k : {1u, 3u, 7u, 49u, 50u}) {
        PageCache cache(file, 0, n, 40, budget_for(n, k, 40), "deferred");
        ASSERT_EQ(cache.slot_count(), k);
        std::vector<int> seen_in(n, 0);
        uint32_t unseen = n;
        int iteration = 0;
        while (unseen > 0) {
            ++iteration;
            ASSERT_LE(iteration, int(n / k) + 3) << "k " << k;
            uint32_t outstanding = 0;
            for (uint32_t p = 0; p < n; ++p) {
                if (seen_in[p]) continue;
                if (const uint8_t* bytes = cache.view().cached(p)) {
                    EXPECT_EQ(std::memcmp(bytes, f.pages[p].raw.data(), 40), 0);
                    seen_in[p] = iteration;
                    --unseen;
                } else {
                    ++outstanding;
                }
                cache.view().request(p);  // a use, or a request
            }
            EXPECT_EQ(cache.swap_requested_pages(), std::min(k, outstanding)) << "k " << k;
            expect_consistent(cache, f.pages);
        }
        for (uint32_t p = 0; p < n; ++p) EXPECT_EQ(seen_in[p], int(p / k) + 2) << "k " << k << ", page " << p;
        EXPECT_EQ(cache.stats().pages_read, n) << "k " << k;
        EXPECT_EQ(cache.stats().evictions, n - k) << "k " << k;
    }
}

TEST(PageCache, WasReadMarksThePagesCachedInEarlierIterations) {
    Fixture f("wasread", random_pages(6, 16, 16, 10));
    PackFile file(f.path);
    PageCache cache(file, 0, 6, 16, budget_for(6, 3, 16), "wasread");
    request(cache, {0, 1, 2});
    cache.swap_requested_pages();
    request(cache, {0, 0, 1});
    cache.swap_requested_pages();  // 0:1 1:1 2:0
    cache.mark_cached_as_read();
    for (uint32_t p : {0u, 1u, 2u}) EXPECT_TRUE(cache.view().was_read(p));
    EXPECT_EQ(time_used(cache.view().descriptor(0)), 1u);  // marking does not count a use
    for (uint32_t p : {3u, 4u, 5u}) EXPECT_FALSE(cache.view().was_read(p));
    // A page with WasRead may be evicted like any other, and keeps WasRead
    // (no ray of this loop needs it again); the page that comes in is unread.
    request(cache, {0, 3});
    cache.swap_requested_pages();  // 0:2 1:1 2:0: 2 goes
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{0, 1, 3}));
    EXPECT_TRUE(cache.view().was_read(0));
    EXPECT_TRUE(cache.view().was_read(1));
    EXPECT_FALSE(cache.view().was_read(3));
    EXPECT_TRUE(cache.view().was_read(2));
    EXPECT_TRUE(cache.view().descriptor(2) & kOutOfCore);
    // Evicted and loaded again (asked for by a new loop's ray): unread.
    request(cache, {2});
    cache.swap_requested_pages();  // 3:0 goes
    EXPECT_FALSE(cache.view().was_read(2));
    cache.clear_was_read();
    for (uint32_t p = 0; p < 6; ++p) EXPECT_FALSE(cache.view().was_read(p));
    EXPECT_EQ(time_used(cache.view().descriptor(0)), 2u);
    expect_consistent(cache, f.pages);
}

TEST(PageCache, StatisticsCountRequestsReadsAndEvictions) {
    Fixture f("stats", random_pages(6, 10, 200, 11));
    PackFile file(f.path);
    PageCache cache(file, 0, 6, 200, budget_for(6, 2, 200), "stats");
    uint64_t stored = 0;
    auto stored_of = [&](uint32_t p) { return uint64_t(stored_bytes(f.pages[p]).size()); };
    request(cache, {0, 1, 4});  // 3 misses; pages 0 and 1 loaded, 4 deferred (1 is zstd-framed)
    EXPECT_EQ(cache.swap_requested_pages(), 2u);
    stored += stored_of(0) + stored_of(1);
    request(cache, {0, 1, 4});  // 2 hits, 1 miss: 4 replaces 0 (0:1 1:1, 0 first)
    EXPECT_EQ(cache.swap_requested_pages(), 1u);
    stored += stored_of(4);
    const PageCacheStats& s = cache.stats();
    EXPECT_EQ(s.swaps, 2u);
    EXPECT_EQ(s.requests, 6u);
    EXPECT_EQ(s.hits, 2u);
    EXPECT_EQ(s.misses, 4u);
    EXPECT_EQ(s.pages_read, 3u);
    EXPECT_EQ(s.evictions, 1u);
    EXPECT_EQ(s.bytes_read, stored);
    EXPECT_DOUBLE_EQ(s.hit_rate(), 2.0 / 6.0);
    EXPECT_GE(s.io_ms, 0.0);
    EXPECT_GE(s.manage_ms, 0.0);
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{1, 4}));
    cache.clear();  // stats kept
    EXPECT_EQ(cache.stats().pages_read, 3u);
    EXPECT_EQ(cache.cached_count(), 0u);
    EXPECT_TRUE(cached_set(cache).empty());
    request(cache, {5});
    EXPECT_EQ(cache.swap_requested_pages(), 1u);
    expect_consistent(cache, f.pages);
    cache.reset_stats();
    EXPECT_EQ(cache.stats().requests, 0u);
    EXPECT_EQ(cache.stats().hit_rate(), 1.0);
}

TEST(PageCache, ACorruptedPageIsAnErrorAndStaysOut) {
    Fixture f("corrupt", random_pages(8, 64, 64, 12));
    {
        std::fstream io(f.path, std::ios::in | std::ios::out | std::ios::binary);
        io.seekp(std::streamoff(f.offsets[3] + 17));
        const char flipped = char(f.pages[3].raw[17] ^ 0x40);  // page 3 is stored plain
        io.write(&flipped, 1);
    }
    PackFile file(f.path);
    PageCache cache(file, 0, 8, 64, budget_for(8, 3, 64), "geometry cache");
    request(cache, {2, 3, 4});
    std::string m = error_of([&] { cache.swap_requested_pages(); });
    EXPECT_NE(m.find("geometry cache"), std::string::npos) << m;
    EXPECT_NE(m.find("checksum"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{2, 4}));
    expect_consistent(cache, f.pages);
    EXPECT_EQ(cache.stats().pages_read, 2u);
    // Its slot is free again: the next request takes it without an eviction.
    request(cache, {5});
    EXPECT_EQ(cache.swap_requested_pages(), 1u);
    EXPECT_EQ(cache.stats().evictions, 0u);
    expect_consistent(cache, f.pages);
    // Through an eviction: the evicted page is gone, the slot free, the rest intact.
    request(cache, {2, 4});
    cache.swap_requested_pages();  // 2:1 4:1 5:0
    request(cache, {3});
    m = error_of([&] { cache.swap_requested_pages(); });  // 5 goes, 3 fails
    EXPECT_NE(m.find("checksum"), std::string::npos) << m;
    EXPECT_EQ(cached_set(cache), (std::set<uint32_t>{2, 4}));
    expect_consistent(cache, f.pages);
    request(cache, {6, 7});  // one free slot, then an eviction
    EXPECT_EQ(cache.swap_requested_pages(), 2u);
    EXPECT_EQ(cache.cached_count(), 3u);
    expect_consistent(cache, f.pages);
    for (int i = 0; i < 30; ++i) {
        request(cache, {uint32_t(i % 8), uint32_t((i * 5) % 8)});
        error_of([&] { cache.swap_requested_pages(); });
        expect_consistent(cache, f.pages);
        EXPECT_FALSE(is_cached(cache, 3));
    }
}

// Random serial workloads of every density, against the model.
TEST(PageCache, MatchesTheSerialModel) {
    Fixture f("model", random_pages(150, 8, 24, 13));
    PackFile file(f.path);
    std::mt19937 rng(14);
    for (uint32_t trial = 0; trial < 30; ++trial) {
        const uint32_t pages = 1 + rng() % 150;
        const uint32_t slots = 1 + rng() % pages;
        PageCache cache(file, 0, pages, 24, budget_for(pages, slots, 24), "model");
        ASSERT_EQ(cache.slot_count(), slots);
        Model model(pages, slots);
        for (int swap = 0; swap < 60; ++swap) {
            const uint32_t density = rng() % 4;  // none, a few, many, all
            const uint32_t n = density == 0   ? 0
                               : density == 1 ? 1 + rng() % 4
                               : density == 2 ? uint32_t(rng() % (2 * pages))
                                              : pages;
            for (uint32_t i = 0; i < n; ++i) {
                const uint32_t p = density == 3 ? i : uint32_t(rng() % pages);
                cache.view().request(p);
                model.request(p);
            }
            if (rng() % 8 == 0) {
                cache.mark_cached_as_read();
                model.mark_cached_as_read();
            }
            if (rng() % 16 == 0) {
                cache.clear_was_read();
                model.clear_was_read();
            }
            const size_t loaded = cache.swap_requested_pages();
            EXPECT_EQ(loaded, model.swap());
            const std::string where = "trial " + std::to_string(trial) + ", swap " + std::to_string(swap);
            expect_matches(cache, model, where);
            if (HasFatalFailure()) return;
            expect_consistent(cache, f.pages);
        }
    }
}

// The same with a few corrupted pages: a swap that reads one throws, the
// others of that swap are loaded, and the failed page's slot is free (so
// later swaps take free slots after evictions).
TEST(PageCache, MatchesTheSerialModelWithCorruptedPages) {
    Fixture f("model_corrupt", random_pages(120, 8, 24, 17));
    const std::set<uint32_t> bad = {5, 40, 41, 97};
    {
        std::fstream io(f.path, std::ios::in | std::ios::out | std::ios::binary);
        for (uint32_t p : bad) {
            io.seekp(std::streamoff(f.offsets[p] + 3));  // past a zstd frame's magic too: its checksum fails
            const char flipped = char(~stored_bytes(f.pages[p])[3]);
            io.write(&flipped, 1);
        }
    }
    PackFile file(f.path);
    std::mt19937 rng(18);
    uint32_t failures = 0;
    for (uint32_t trial = 0; trial < 20; ++trial) {
        const uint32_t pages = 60 + rng() % 61;
        const uint32_t slots = 1 + rng() % 30;
        PageCache cache(file, 0, pages, 24, budget_for(pages, slots, 24), "model");
        Model model(pages, slots, bad);
        for (int swap = 0; swap < 60; ++swap) {
            const uint32_t n = rng() % 3 == 0 ? 1 + rng() % 3 : rng() % pages;
            for (uint32_t i = 0; i < n; ++i) {
                const uint32_t p = uint32_t(rng() % pages);
                cache.view().request(p);
                model.request(p);
            }
            size_t loaded = 0;
            const std::string error = error_of([&] { loaded = cache.swap_requested_pages(); });
            const size_t expected = model.swap();
            EXPECT_EQ(!error.empty(), model.failed) << error;
            if (error.empty()) {
                EXPECT_EQ(loaded, expected);
            }
            failures += model.failed;
            const std::string where = "trial " + std::to_string(trial) + ", swap " + std::to_string(swap);
            expect_matches(cache, model, where);
            if (HasFatalFailure()) return;
            expect_consistent(cache, f.pages);
        }
    }
    EXPECT_GT(failures, 20u);
}

// Many threads request (skewed) random pages and read the cached ones during
// an iteration, as rays do; the swaps between iterations must match the
// model fed the same requests.
TEST(PageCache, ConcurrentRequestsMatchTheSerialModel) {
    const uint32_t pages = 400;
    Fixture f("concurrent", random_pages(pages, 32, 128, 15));
    PackFile file(f.path);
    PageCache cache(file, 0, pages, 128, budget_for(pages, 37, 128), "concurrent");
    Model model(pages, 37);
    std::mt19937 rng(16);
    for (int iteration = 0; iteration < 80; ++iteration) {
        std::vector<uint32_t> wanted(4000);
        for (uint32_t& p : wanted) {
            const uint32_t r = rng() % 1000;
            p = (r * r / 1000 + uint32_t(iteration) * 3) % pages;  // hot pages drift
        }
        const PageTableView view = cache.view();
        std::atomic<uint32_t> wrong{0};
        parallel::for_range(size_t(0), wanted.size(), size_t(64), [&](size_t lo, size_t hi) {
            for (size_t i = lo; i < hi; ++i) {
                const uint32_t p = wanted[i];
                if (const uint8_t* bytes = view.cached(p))
                    if (std::memcmp(bytes, f.pages[p].raw.data(), 32) != 0) ++wrong;
                view.request(p);
            }
        });
        EXPECT_EQ(wrong.load(), 0u);
        for (uint32_t p : wanted) model.request(p);
        EXPECT_EQ(cache.swap_requested_pages(), model.swap());
        expect_matches(cache, model, "iteration " + std::to_string(iteration));
        if (HasFatalFailure()) return;
        expect_consistent(cache, f.pages);
    }
    EXPECT_GT(cache.stats().evictions, 0u);
    EXPECT_GT(cache.stats().hits, 0u);
}

}  // namespace
}  // namespace rf::pack

namespace rf::pack {
namespace {

// The reader pool runs every index of a run exactly once, any number of
// runs in a row, from several caller threads at once (one run at a time),
// and a run of nothing returns at once.
TEST(ReaderPool, RunsEveryIndexOnceWhoeverCalls) {
    ReaderPool pool(8);
    pool.run(0, [](size_t) { FAIL() << "a run of nothing ran something"; });
    for (size_t count : {1u, 2u, 7u, 8u, 9u, 1000u}) {
        std::vector<std::atomic<int>> hits(count);
        pool.run(count, [&](size_t i) { hits[i].fetch_add(1); });
        for (size_t i = 0; i < count; ++i) ASSERT_EQ(hits[i].load(), 1) << "count " << count << ", index " << i;
    }
    std::vector<std::thread> callers;
    std::atomic<int> total{0};
    for (int c = 0; c < 4; ++c)
        callers.emplace_back([&] {
            for (int r = 0; r < 50; ++r) pool.run(17, [&](size_t) { total.fetch_add(1); });
        });
    for (std::thread& t : callers) t.join();
    EXPECT_EQ(total.load(), 4 * 50 * 17);
    // The shared pool, as the page managers use it.
    std::atomic<int> shared{0};
    ReaderPool::shared().run(100, [&](size_t) { shared.fetch_add(1); });
    EXPECT_EQ(shared.load(), 100);
}

// io_uring reads (where the kernel allows them; the test says so and skips
// otherwise): more reads than the queue depth, of every size, each equal to
// a pread of the same range; a read past the end of the file fails with
// EIO, the others still succeed.
TEST(UringReader, ReadsEqualPreadsAndAReadPastTheEndFails) {
    std::string why;
    const std::unique_ptr<UringReader> reader = UringReader::create(why);
    if (!reader) GTEST_SKIP() << "no io_uring here: " << why;
    const std::string path = test::temp_dir("uring_reader") + "/bytes.bin";
    std::vector<uint8_t> bytes(3 << 20);
    std::mt19937 rng(3);
    for (uint8_t& b : bytes) b = uint8_t(rng());
    {
        std::ofstream out(path, std::ios::binary);
        out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    }
    const int fd = ::open(path.c_str(), O_RDONLY);
    ASSERT_GE(fd, 0);
    const size_t count = 3 * UringReader::kQueueDepth + 5;
    std::vector<std::vector<uint8_t>> into(count);
    std::vector<UringReader::Read> reads(count);
    for (size_t i = 0; i < count; ++i) {
        const uint32_t size = i % 5 == 0 ? 0u : uint32_t(1 + rng() % (200 << 10));
        const uint64_t offset = rng() % (bytes.size() - size);
        into[i].assign(size, 0xAB);
        reads[i] = {fd, offset, size, into[i].data(), 0};
    }
    std::vector<uint8_t> past(4096);
    reads.push_back({fd, bytes.size() - 100, 4096, past.data(), 0});
    reader->read_all(reads);
    for (size_t i = 0; i < count; ++i) {
        ASSERT_EQ(reads[i].error, 0) << i;
        ASSERT_TRUE(std::equal(into[i].begin(), into[i].end(), bytes.begin() + long(reads[i].offset))) << i;
    }
    EXPECT_EQ(reads.back().error, EIO);
    ::close(fd);
}

}  // namespace
}  // namespace rf::pack
