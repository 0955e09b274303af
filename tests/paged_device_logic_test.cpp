// The device side of paged scenes (backend/cuda/paged_device.cu) checked on
// the CPU: run_device_query_loop and its steps (ooc/device_page_cache_steps.h)
// over a replay backend whose "device" arrays are host vectors and whose
// kernels run their threads in shuffled orders (the ray starts, the
// iterations, the scatter's words, the answers), with the stable sort and
// compaction CUB does. On a paged file of the spheres scene, with device
// pools of 1, 3 and many slots, host caches smaller than the scene and
// staging fills of one page or of Garanzha 2014's 1 MB:
//   - closest and any hits equal PagedEngine's on the same file, exactly;
//   - every swap admits min(requested, slots) of the requested pages and
//     nothing else, so every request is served (the loop ends with every
//     ray finished); after every scatter each cached page's slot holds its
//     bytes, and no slot holds two pages;
//   - device and host memory stay within their budgets;
// and: the swap decision equals the host PageCache's (the same algorithm
// of Garanzha 2014) descriptor for descriptor on random request sequences; a
// scatter that drops a word is caught; a corrupted page is an rf::Error
// that leaves the device pool empty.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "accel_test_rays.h"
#include "ooc/device_page_cache_steps.h"
#include "ooc/pack_file.h"
#include "ooc/page_cache.h"
#include "ooc/paged_engine.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "test_paths.h"

namespace rf::pack {
namespace {

// ------------------------------------------------------------------ fixture

struct Fixture {
    std::string path;
    std::shared_ptr<const PackFile> file;
    std::vector<std::vector<uint8_t>> pages;  // every geometry page, raw
    std::vector<Ray> rays;
    size_t host_slot = 0;                     // the largest page
};

// The spheres scene, paged into small pages (many of them).
const Fixture& fixture() {
    static const std::unique_ptr<Fixture> f = [] {
        auto out = std::make_unique<Fixture>();
        Scene scene = make_builtin_scene("spheres");
        scene.finalize();
        out->path = test::temp_dir("paged_device_logic") + "/spheres.rfpack";
        PagedWriteOptions options;
        options.quads_per_page = 256;
        convert_to_paged(scene, out->path, options);
        out->file = std::make_shared<const PackFile>(out->path);
        std::vector<uint8_t> scratch;
        out->pages.resize(out->file->header().geometry_pages);
        for (uint32_t p = 0; p < out->pages.size(); ++p) {
            out->file->read_page(p, out->pages[p], scratch);
            out->host_slot = std::max(out->host_slot, out->pages[p].size());
        }
        out->rays = test::make_rays(SceneGeometry::build(scene), 2500, 5);
        return out;
    }();
    return *f;
}

// The budget of a host PageCache with exactly `slots` slots.
size_t host_budget_for(uint32_t pages, uint32_t slots, size_t slot_bytes) {
    return size_t(pages) * PageCache::kTableBytesPerPage +
           size_t(slots) * (slot_bytes + PageCache::kBookkeepingBytesPerSlot) + slot_bytes / 2;
}

std::vector<uint32_t> shuffled(uint32_t count, std::mt19937& rng) {
    std::vector<uint32_t> order(count);
    std::iota(order.begin(), order.end(), 0u);
    std::shuffle(order.begin(), order.end(), rng);
    return order;
}

// ------------------------------------------------------------ replay backend

enum class Bug { None, ScatterDropsLastWord };

// What the replay saw.
struct ReplayChecks {
    uint64_t swaps = 0, admitted = 0;
    uint64_t wrong_admissions = 0;  // swaps that admitted other than min(requested, slots) requested pages
    uint64_t shared_slots = 0;      // slots claimed by two cached pages
    uint64_t wrong_slot_bytes = 0;  // cached pages whose slot does not hold their bytes
    uint64_t oversized_fills = 0;
    uint64_t unfinished = 0;        // rays not finished when their loop ended
};

// The device of paged_device.cu in host memory (see the file's comment).
template <bool kAnyHit>
class ReplayBackend {
public:
    ReplayBackend(const Fixture& f, uint32_t slots, const StagingLayout& layout, uint32_t seed, Bug bug = Bug::None)
        : f_(f), layout_(layout), slots_(slots), rng_(seed), bug_(bug) {
        const uint32_t page_count = uint32_t(f.pages.size());
        descriptors_.assign(page_count, kOutOfCore);
        pool_.assign(size_t(slots) * layout.slot_bytes, 0xCD);
        staging_.resize(layout.bytes());
        for (auto& fill : fills_) fill.resize(layout.bytes());
        const PackFile& file = *f.file;
        view_ = make_paged_view(file,
                                {file.pages().data(), file.page_roots().data(), file.cell_roots().data(), file.middle_nodes().data(),
                                 file.top_nodes().data(), file.top_refs().data(), file.instances().data()},
                                PageTableView{descriptors_.data(), pool_.data(), layout.slot_bytes, page_count});
    }

    // A loop begins (the pool stays, as on the device).
    void begin(uint32_t n) {
        states_.resize(n);
        keys_.resize(n);
        order_.resize(n);
        queue_[0].resize(n);
        queue_[1].resize(n);
        again_.resize(n);
        const DeviceRayArrays a = arrays(nullptr);
        for (uint32_t i : shuffled(n, rng_)) device_start_step(a, f_.file->resident().bounds, i);
        // CUB's radix sort of (key, ray) pairs is stable.
        queue_[0] = order_;
        std::stable_sort(queue_[0].begin(), queue_[0].end(), [&](uint32_t x, uint32_t y) { return keys_[x] < keys_[y]; });
        current_ = 0;
    }

    uint32_t iterate(uint32_t count, std::span<const uint32_t> fresh, bool every_page_fresh) {
        const DeviceRayArrays a = arrays(queue_[current_].data());
        const FreshPages f = every_page_fresh ? FreshPages{} : FreshPages{fresh.data(), uint32_t(fresh.size())};
        PagedCounters c;
        for (uint32_t k : shuffled(count, rng_)) device_iteration_step<kAnyHit>(view_, a, k, f, c);
        counters.cells += c.cells;
        counters.middle += c.middle;
        counters.pages += c.pages;
        counters.nodes += c.nodes;
        counters.quads += c.quads;
        counters.ray_iterations += c.runs;
        uint32_t kept = 0;  // DeviceSelect::Flagged keeps the order
        for (uint32_t k = 0; k < count; ++k)
            if (again_[k]) queue_[1 - current_][kept++] = queue_[current_][k];
        current_ = 1 - current_;
        return kept;
    }

    // The requests the swap will see, and the cached set before it.
    void download_descriptors(std::span<uint32_t> host) {
        std::copy(descriptors_.begin(), descriptors_.end(), host.begin());
        requested_missing_.clear();
        cached_before_.clear();
        for (uint32_t p = 0; p < descriptors_.size(); ++p) {
            const uint32_t d = descriptors_[p];
            if ((d & kOutOfCore) && (d & kRequested)) requested_missing_.insert(p);
            if (!(d & kOutOfCore)) cached_before_.insert(p);
        }
        swapped_ = true;
    }

    // After a swap and its scatters: the admissions and the pool checked.
    // A loop's last swap (its rays all done; an any-hit ray may have asked
    // for a page before finding a hit) is uploaded by the next loop, and
    // checked then.
    void upload_descriptors(std::span<const uint32_t> host) {
        std::copy(host.begin(), host.end(), descriptors_.begin());
        if (!swapped_) return;  // the first loop's first upload
        swapped_ = false;
        ++checks.swaps;
        size_t admitted = 0;
        bool wrong = false;
        std::set<uint32_t> slots;
        for (uint32_t p = 0; p < descriptors_.size(); ++p) {
            const uint32_t d = descriptors_[p];
            if (d & kOutOfCore) continue;
            if (!cached_before_.count(p)) {
                ++admitted;
                wrong = wrong || !requested_missing_.count(p);
            }
            if (!slots.insert(d & kSlotMask).second || (d & kSlotMask) >= slots_) ++checks.shared_slots;
            const std::vector<uint8_t>& raw = f_.pages[p];
            if (std::memcmp(pool_.data() + uint64_t(d & kSlotMask) * layout_.slot_bytes, raw.data(), raw.size()) != 0)
                ++checks.wrong_slot_bytes;
        }
        wrong = wrong || admitted != std::min<size_t>(requested_missing_.size(), slots_);
        checks.wrong_admissions += wrong ? 1 : 0;
        checks.admitted += admitted;
    }

    uint8_t* begin_fill() { return fills_[next_fill_].data(); }

    // The copy, then the scatter's (page, word) threads in a shuffled order.
    void end_fill(uint32_t pages, uint64_t bytes) {
        if (pages > layout_.max_pages || bytes > layout_.bytes()) ++checks.oversized_fills;
        std::memcpy(staging_.data(), fills_[next_fill_].data(), bytes);
        next_fill_ = 1 - next_fill_;
        const auto* table = reinterpret_cast<const StagedPage*>(staging_.data());
        std::vector<std::pair<uint32_t, uint32_t>> threads;
        for (uint32_t b = 0; b < pages; ++b) {
            const uint32_t words = table[b].words - (bug_ == Bug::ScatterDropsLastWord ? 1 : 0);
            for (uint32_t w = 0; w < words; ++w) threads.emplace_back(b, w);
        }
        std::shuffle(threads.begin(), threads.end(), rng_);
        for (const auto& [b, w] : threads) scatter_word(staging_.data(), table[b], pool_.data(), layout_.slot_bytes, w);
    }

    void finish(uint32_t n) {
        hits.assign(n, Hit{});
        occluded.assign(n, 0);
        for (uint32_t i : shuffled(n, rng_)) device_finish_step(states_.data(), i, hits.data(), occluded.data());
        for (const PagedRayState& s : states_) checks.unfinished += s.restart != kRayFinished ? 1 : 0;
    }

    ReplayChecks checks;
    EngineStats counters;  // the kernel's counters, summed
    std::vector<Hit> hits;
    std::vector<uint8_t> occluded;
    [[nodiscard]] size_t device_bytes() const {
        return descriptors_.size() * sizeof(uint32_t) + staging_.size() + pool_.size();
    }

private:
    DeviceRayArrays arrays(const uint32_t* pending) {
        return {f_.rays.data(), states_.data(), keys_.data(), order_.data(), pending, again_.data()};
    }

    const Fixture& f_;
    StagingLayout layout_;
    uint32_t slots_;
    std::mt19937 rng_;
    Bug bug_;
    PagedSceneView view_;
    std::vector<uint32_t> descriptors_;
    std::vector<uint8_t> pool_, staging_, fills_[2];
    int next_fill_ = 0;
    std::vector<PagedRayState> states_;
    std::vector<uint32_t> keys_, order_, queue_[2];
    std::vector<uint8_t> again_;
    int current_ = 0;
    bool swapped_ = false;  // a swap since the last upload
    std::set<uint32_t> requested_missing_, cached_before_;
};

// PagedEngine's answers on the same file (a roomy cache).
struct Expected {
    std::vector<Hit> hits;
    std::vector<uint8_t> occluded;
};

const Expected& expected() {
    static const Expected e = [] {
        const Fixture& f = fixture();
        PagedEngine engine(f.file, {size_t(64) << 20, size_t(1) << 20}, 0);
        Expected out{std::vector<Hit>(f.rays.size()), std::vector<uint8_t>(f.rays.size())};
        engine.intersect(f.rays, out.hits);
        engine.occluded(f.rays, out.occluded);
        return out;
    }();
    return e;
}

struct Pools {
    uint32_t device_slots;
    uint32_t host_slots;
    uint64_t staging_bytes;
};

std::string describe(const Pools& s) {
    return "device slots " + std::to_string(s.device_slots) + ", host slots " + std::to_string(s.host_slots) +
           ", staging " + std::to_string(s.staging_bytes);
}

// Both query kinds through the replay, checked as the file's comment says.
template <bool kAnyHit>
void replay_and_check(const Pools& s, uint32_t seed) {
    const Fixture& f = fixture();
    const uint32_t page_count = uint32_t(f.pages.size());
    const StagingLayout layout = staging_layout(s.staging_bytes, round_up_16(f.host_slot));
    const uint64_t device_budget = device_budget_for_slots(page_count, layout, s.device_slots);
    const uint32_t slots = device_slots_within_budget(page_count, layout, device_budget);
    ASSERT_EQ(slots, s.device_slots);
    const size_t host_budget = host_budget_for(page_count, s.host_slots, f.host_slot);
    PageCache host(*f.file, 0, page_count, f.host_slot, host_budget, "host geometry cache");
    ASSERT_EQ(host.slot_count(), s.host_slots);
    DevicePoolPlanner planner(page_count, slots);
    DeviceLoopStats stats;
    const std::string what = describe(s) + (kAnyHit ? ", any hit" : ", closest hit");
    ReplayBackend<kAnyHit> backend(f, slots, layout, seed);
    // Two loops on the same caches: the second starts warm.
    for (int loop = 0; loop < 2; ++loop) {
        run_device_query_loop(backend, planner, layout, host, *f.file, uint32_t(f.rays.size()), stats);
        EXPECT_LE(host.memory_bytes(), host_budget) << what;
        const Expected& e = expected();
        for (size_t i = 0; i < f.rays.size(); ++i) {
            if (kAnyHit) {
                ASSERT_EQ(backend.occluded[i], e.occluded[i]) << what << ", ray " << i;
                continue;
            }
            const Hit& got = backend.hits[i];
            const Hit& want = e.hits[i];
            ASSERT_EQ(got.prim, want.prim) << what << ", ray " << i;
            ASSERT_EQ(got.t, want.t) << what << ", ray " << i;
            ASSERT_EQ(got.u, want.u) << what << ", ray " << i;
            ASSERT_EQ(got.v, want.v) << what << ", ray " << i;
        }
    }
    backend.upload_descriptors(planner.descriptors());  // what the next loop would upload first: the last swap checked
    const ReplayChecks& c = backend.checks;
    EXPECT_EQ(c.unfinished, 0u) << what;
    EXPECT_EQ(c.wrong_admissions, 0u) << what;
    EXPECT_EQ(c.shared_slots, 0u) << what;
    EXPECT_EQ(c.wrong_slot_bytes, 0u) << what;
    EXPECT_EQ(c.oversized_fills, 0u) << what;
    EXPECT_EQ(c.swaps, stats.iterations) << what;  // every swap checked
    EXPECT_EQ(c.admitted, planner.stats().admitted) << what;
    EXPECT_GT(c.admitted, 0u) << what;
    EXPECT_LE(backend.device_bytes(), device_budget) << what;

    // The CPU engine with a pool of as many slots runs the same schedule:
    // the same decisions (SwapDecisionEqualsTheHostPageCache), so the same
    // iterations, pages searched and evictions.
    PagedEngine same_pool(f.file, {host_budget_for(page_count, slots, f.host_slot), size_t(1) << 20}, 0);
    ASSERT_EQ(same_pool.geometry_cache().slot_count(), slots);
    for (int loop = 0; loop < 2; ++loop) {
        std::vector<Hit> hits(f.rays.size());
        std::vector<uint8_t> occluded(f.rays.size());
        if (kAnyHit) same_pool.occluded(f.rays, occluded);
        else same_pool.intersect(f.rays, hits);
    }
    const EngineStats& cpu = same_pool.stats();
    EXPECT_EQ(stats.iterations, cpu.iterations) << what;
    EXPECT_EQ(backend.counters.ray_iterations, cpu.ray_iterations) << what;  // runs: rays that did not wait
    EXPECT_EQ(backend.counters.cells, cpu.cells) << what;
    EXPECT_EQ(backend.counters.middle, cpu.middle) << what;
    EXPECT_EQ(backend.counters.pages, cpu.pages) << what;
    EXPECT_EQ(backend.counters.nodes, cpu.nodes) << what;
    EXPECT_EQ(backend.counters.quads, cpu.quads) << what;
    EXPECT_EQ(planner.stats().evictions, same_pool.geometry_cache().stats().evictions) << what;
    EXPECT_EQ(planner.stats().admitted, same_pool.geometry_cache().stats().pages_read) << what;
    EXPECT_GT(stats.fills, 0u);
    EXPECT_EQ(stats.pages_staged, planner.stats().admitted);
}

// ------------------------------------------------------------------- tests

TEST(PagedDeviceLogic, TheFixtureHasManyPages) {
    const Fixture& f = fixture();
    EXPECT_GE(f.pages.size(), 12u);
    size_t found = 0;
    for (const Hit& h : expected().hits) found += h.found() ? 1 : 0;
    EXPECT_GT(found, f.rays.size() / 3);
}

TEST(PagedDeviceLogic, HitsEqualPagedEngineWithSmallDevicePools) {
    const Fixture& f = fixture();
    const uint32_t n = uint32_t(f.pages.size());
    const uint64_t one_page = 1, gather = kDefaultStagingBytes;
    for (const Pools& s : {Pools{1, 1, one_page}, Pools{1, n / 3, gather}, Pools{3, 2, gather}, Pools{3, n / 3, one_page}}) {
        replay_and_check<false>(s, 11);
        replay_and_check<true>(s, 12);
    }
}

TEST(PagedDeviceLogic, HitsEqualPagedEngineWithLargeDevicePools) {
    const Fixture& f = fixture();
    const uint32_t n = uint32_t(f.pages.size());
    const uint64_t one_page = 1, gather = kDefaultStagingBytes;
    // A pool of a quarter of the pages, and one holding them all, behind host caches of 1, 2 and n/3 slots.
    for (const Pools& s : {Pools{n / 4, 2, gather}, Pools{n, 1, gather}, Pools{n, n / 3, one_page}, Pools{n, n / 3, gather}}) {
        replay_and_check<false>(s, 21);
        replay_and_check<true>(s, 22);
    }
}

// The device pool's swap decision is Garanzha 2014's, as the host manager makes
// it: the same descriptors after every swap on random request sequences.
TEST(PagedDeviceLogic, SwapDecisionEqualsTheHostPageCache) {
    const Fixture& f = fixture();
    const uint32_t n = uint32_t(f.pages.size());
    std::mt19937 rng(3);
    for (uint32_t slots : {1u, 2u, 5u, n / 2, n}) {
        PageCache cache(*f.file, 0, n, f.host_slot, host_budget_for(n, slots, f.host_slot), "model");
        ASSERT_EQ(cache.slot_count(), slots);
        DevicePoolPlanner planner(n, slots);
        for (int round = 0; round < 200; ++round) {
            if (round % 37 == 0) {
                cache.clear_was_read();
                planner.clear_was_read();
            }
            // A skewed workload: low page ids are popular.
            const uint32_t requests = std::uniform_int_distribution<uint32_t>(0, 2 * slots + 2)(rng);
            for (uint32_t r = 0; r < requests; ++r) {
                const uint32_t page = std::min(n - 1, uint32_t(std::exponential_distribution<double>(8.0 / n)(rng)));
                cache.view().request(page);
                planner.descriptors()[page] |= kRequested;
            }
            const size_t loaded = cache.swap_requested_pages();
            const size_t admitted = planner.swap_requested_pages().size();
            ASSERT_EQ(loaded, admitted) << "slots " << slots << ", round " << round;
            for (uint32_t p = 0; p < n; ++p)
                ASSERT_EQ(planner.descriptors()[p], cache.view().descriptor(p))
                    << "slots " << slots << ", round " << round << ", page " << p;
            if (round % 3 == 0) {
                cache.mark_cached_as_read();
                planner.mark_cached_as_read();
            }
        }
        EXPECT_EQ(planner.stats().evictions, cache.stats().evictions);
        EXPECT_EQ(planner.stats().hits, cache.stats().hits);
        EXPECT_EQ(planner.cached_count(), cache.cached_count());
    }
}

TEST(PagedDeviceLogic, BudgetsGiveTheirSlotsAndNamesTheNumbers) {
    const StagingLayout layout = staging_layout(kDefaultStagingBytes, 4096);
    EXPECT_EQ(layout.max_pages, 256u);
    EXPECT_EQ(staging_layout(1, 4096).max_pages, 1u);
    for (uint32_t slots : {1u, 7u, 100u})
        EXPECT_EQ(device_slots_within_budget(100, layout, device_budget_for_slots(100, layout, slots) + 4095), slots);
    EXPECT_EQ(device_slots_within_budget(100, layout, uint64_t(1) << 40), 100u);  // one slot per page at most
    try {
        (void)device_slots_within_budget(100, layout, device_budget_for_slots(100, layout, 1) - 1);
        ADD_FAILURE() << "a budget without a slot was accepted";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find(std::to_string(device_budget_for_slots(100, layout, 1) - 1)), std::string::npos) << m;
        EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
}

// The checks see a broken scatter: a slot missing its last 16 bytes.
TEST(PagedDeviceLogic, AScatterDroppingAWordIsCaught) {
    const Fixture& f = fixture();
    const uint32_t n = uint32_t(f.pages.size());
    const StagingLayout layout = staging_layout(kDefaultStagingBytes, round_up_16(f.host_slot));
    PageCache host(*f.file, 0, n, f.host_slot, host_budget_for(n, n, f.host_slot), "host");
    DevicePoolPlanner planner(n, n);
    DeviceLoopStats stats;
    ReplayBackend<false> backend(f, n, layout, 5, Bug::ScatterDropsLastWord);
    run_device_query_loop(backend, planner, layout, host, *f.file, uint32_t(f.rays.size()), stats);
    EXPECT_GT(backend.checks.wrong_slot_bytes, 0u);
}

// A page the host level cannot read: one line naming the file, and the
// device pool emptied (the next loop starts from an empty table).
TEST(PagedDeviceLogic, ACorruptedPageIsAnErrorAndEmptiesThePool) {
    const Fixture& f = fixture();
    const std::string path = test::temp_dir("paged_device_logic_corrupt") + "/corrupt.rfpack";
    std::filesystem::copy_file(f.path, path, std::filesystem::copy_options::overwrite_existing);
    const uint32_t n = uint32_t(f.pages.size());
    {
        std::fstream io(path, std::ios::in | std::ios::out | std::ios::binary);
        for (uint32_t p = 0; p < n; ++p) {  // every page: whichever is asked for first fails
            io.seekp(std::streamoff(f.file->directory()[p].offset + 20));
            io.put(char(0x5A ^ f.pages[p][20]));
        }
    }
    Fixture corrupt = f;
    corrupt.file = std::make_shared<const PackFile>(path);
    const StagingLayout layout = staging_layout(kDefaultStagingBytes, round_up_16(f.host_slot));
    PageCache host(*corrupt.file, 0, n, f.host_slot, host_budget_for(n, 2, f.host_slot), "host");
    DevicePoolPlanner planner(n, 3);
    DeviceLoopStats stats;
    ReplayBackend<false> backend(corrupt, 3, layout, 5);
    try {
        run_device_query_loop(backend, planner, layout, host, *corrupt.file, uint32_t(f.rays.size()), stats);
        ADD_FAILURE() << "a corrupted page was served";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find(path), std::string::npos) << m;
        EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
    EXPECT_EQ(planner.cached_count(), 0u);
    for (uint32_t d : planner.descriptors()) EXPECT_EQ(d, kOutOfCore);
}

}  // namespace
}  // namespace rf::pack
