// The CPU's out-of-core query engine for a paged scene (Garanzha 2014,
// ch. 6, adapted from host -> GPU to disk -> host memory): the resident
// levels, the geometry and attribute page managers, and the re-entrant
// loop (Listing 6.1) that runs paged_iteration over all pending rays and
// swaps the requested pages in, until no ray asks for a page.
//
// Rays of a batch are sorted by their 4-byte Garanzha-Loop key (origin and
// direction quantised; render/ray_sort_key.h) and processed in that order
// in contiguous blocks, so the rays of a block meet the same pages (§6.6).
// One query loop runs at a time (the managers' flags are per loop); the
// loop itself is parallel over rays.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "ooc/pack_file.h"
#include "ooc/page_cache.h"
#include "ooc/paged_traversal.h"
#include "render/shading_triangles.h"

namespace rf::pack {

struct EngineBudgets {
    size_t geometry = 0;
    size_t attributes = 0;
};

// What the query loops did since the last reset.
struct EngineStats {
    uint64_t queries = 0;        // rays (closest and any hit)
    uint64_t iterations = 0;     // re-entrant iterations over all loops
    uint64_t ray_iterations = 0; // sum over iterations of the rays that ran in it (not those waiting for their page)
    uint64_t shading_fetches = 0;
    double traversal_ms = 0.0;   // inside the iterations
    double sort_ms = 0.0;
    uint64_t cells = 0, middle = 0, pages = 0, nodes = 0, quads = 0;
    void add(const PagedCounters& c) {
        ray_iterations += c.runs;
        cells += c.cells;
        middle += c.middle;
        pages += c.pages;
        nodes += c.nodes;
        quads += c.quads;
    }
};

class PagedEngine {
public:
    PagedEngine(std::shared_ptr<const PackFile> file, const EngineBudgets& budgets, int threads);

    [[nodiscard]] const PackFile& file() const { return *file_; }
    // Closest hits (Hit::prim = page * kTrianglesPerPageSlot + 2 * quad + half)
    // and any hits. `instances`, when not empty, receives each hit's
    // instance (kNoInstance for a world-space page or a miss): the paged hit
    // record's part that the Hit every kernel uses does not carry.
    void intersect(std::span<const Ray> rays, std::span<Hit> hits, std::span<uint32_t> instances = {});
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded);
    // The shading record of every found hit (misses get a default record),
    // through the attribute manager's own loop; with `instances` (from
    // intersect), records of instanced pages are taken to world space.
    void fetch_shading(std::span<const Hit> hits, std::span<ShadingTriangle> records,
                       std::span<const uint32_t> instances = {});

    [[nodiscard]] PageCache& geometry_cache() { return *geometry_; }
    [[nodiscard]] PageCache& attribute_cache() { return *attributes_; }
    [[nodiscard]] const PageCache& geometry_cache() const { return *geometry_; }
    [[nodiscard]] const PageCache& attribute_cache() const { return *attributes_; }
    [[nodiscard]] const EngineStats& stats() const { return stats_; }
    void reset_stats();
    [[nodiscard]] PagedSceneView view();
    // Caches and resident tables.
    [[nodiscard]] size_t memory_bytes() const;

private:
    template <bool kAnyHit>
    void run_queries(std::span<const Ray> rays, std::span<PagedRayState> states);

    std::shared_ptr<const PackFile> file_;
    std::unique_ptr<PageCache> geometry_;
    std::unique_ptr<PageCache> attributes_;
    int threads_ = 0;
    std::mutex mutex_;  // one query loop at a time
    EngineStats stats_;
    std::vector<PagedRayState> states_;
    std::vector<uint32_t> order_, keys_, pending_;
};

// Page and slot of a paged primitive id.
[[nodiscard]] inline uint32_t page_of(uint32_t prim) { return prim / kTrianglesPerPageSlot; }
[[nodiscard]] inline uint32_t record_of(uint32_t prim) { return prim % kTrianglesPerPageSlot; }

}  // namespace rf::pack
