// `rayforge bench --paged FILE`: what an out-of-core (paged) scene costs
// against the same geometry in core, and how the cost grows as the page
// caches shrink (Garanzha 2014, §6.7.2-6.7.4, tables 6.3/6.4: caches of 1,
// 1/2, 1/10, 1/100 and 1/200 of the scene). The in-core side is a BVH8 over
// the file's own quantised triangles (rf::decode_paged_geometry), so both
// sides trace identical rays through identical geometry; hit counts are
// compared row by row. Built on the public API only.
#pragma once

#include <cstdint>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "rayforge/ooc/paged_scene.h"
#include "rayforge/scene/light.h"

namespace rf::bench {

struct PagedBenchConfig {
    // Cache sizes as fractions of the scene: each page manager gets f times
    // the bytes of its own pages plus its tables (f = 1 holds everything).
    std::vector<double> budgets{1.0, 0.5, 0.1, 0.01, 0.005};
    int width = 1024, height = 768;  // one camera ray per pixel centre, from the file's camera
    int repetitions = 5;             // timed traces per (budget, ray set) after the cold one and a warm-up; medians
    int passes = 4;                  // path-tracing passes per budget (the first is the cold one)
    int max_depth = 3;               // path bounces (Garanzha 2014's 3)
    int threads = 0;                 // 0 = all cores
    // Cold runs from the disk: before each, the file's pages are also dropped
    // from the operating system's cache (otherwise a file that fits in
    // memory is read from it after the first run).
    bool cold_from_disk = false;
    // The shadow set's light; unset: the file's first light (PagedScene
    // lights), and no shadow set when there is none.
    std::optional<Light> light;
};

// Per page manager (geometry, attributes, textures), for one budget.
struct PagedCacheFigures {
    std::string name;
    uint32_t pages = 0, slots = 0;
    size_t budget_bytes = 0;
    bool clamped = false;  // the fraction asked for fewer slots than the manager needs (1; textures 16)
    // Summed over the timed runs (per run: divide by the runs).
    uint64_t requests = 0, hits = 0, pages_read = 0, bytes_read = 0, evictions = 0;
    double io_ms = 0.0, manage_ms = 0.0;
    [[nodiscard]] double hit_rate() const { return requests ? double(hits) / double(requests) : 1.0; }
};

// What one set of timed runs (the cold one, or the warm ones) did, from the
// deltas of PagedScene::caches() and query_stats() around the runs.
struct PagedRunFigures {
    int runs = 0;
    double ms = 0.0;             // median run (path: median pass)
    double mean_ms = 0.0;
    double mrays_per_s = 0.0;    // rays / the median run (path: all rays / the passes' time)
    double bytes_per_ray = 0.0;  // all managers
    double io_ms = 0.0, manage_ms = 0.0, traversal_ms = 0.0, sort_ms = 0.0;  // mean per run
    double iterations_per_loop = 0.0;  // query-loop iterations per batch call (path: per pass)
    double iterations_per_ray = 0.0;   // ray iterations / queries: how often a ray is resumed
    std::vector<PagedCacheFigures> caches;
};

// One (file, budget, workload) row. Workloads: primary, shadow, diffuse1..3
// (bounces of cosine-sampled rays from the previous set's hits), path.
struct PagedBenchRow {
    std::string file, workload;
    double budget = 1.0;
    uint64_t rays = 0;  // per run (path: per pass, both kinds)
    PagedRunFigures cold, warm;
    // Ray sets: the in-core BVH8 on the same rays, and the answers compared.
    double in_core_mrays_per_s = 0.0;
    double slowdown = 0.0;  // in-core / paged Mrays/s (path: ms per pass / the f = 1 run's); 0 = not measured
    uint64_t paged_hits = 0, in_core_hits = 0;  // closest hits, or occluded rays
    double agreement = 0.0;                     // rays with the same answer (and primitive)
    // Path tracing.
    double first_pass_ms = 0.0;
};

// The file and how each budget became slots.
struct PagedFileSummary {
    PagedSceneInfo info;
    Camera camera;
    std::string light;              // how the shadow set was lit ("" = no shadow set)
    uint32_t inferred_page_quads = 0;   // the converter's --page-quads, from the largest page; 0 = unknown
    double mean_page_quads = 0.0;
    size_t geometry_slot_bytes = 0;
    uint64_t in_core_triangles = 0;
    double in_core_build_ms = 0.0;
    std::vector<std::pair<double, std::vector<PagedCacheFigures>>> budgets;  // budget -> managers (no counts)
};

struct PagedFileResult {
    PagedFileSummary summary;
    std::vector<PagedBenchRow> rows;
};

// Every workload at every budget on one paged file; progress on `log`.
// rf::Error for a file that cannot be opened, budgets outside (0, 1], or
// fewer than 2 passes.
PagedFileResult run_paged_bench(const std::string& path, const PagedBenchConfig& config, std::ostream& log);

// The machine and command lines, printed once before the files' tables.
void print_paged_header(std::ostream& out, const PagedBenchConfig& config, const std::string& command);
// One file's info line, budgets and table.
void print_paged_tables(std::ostream& out, const PagedFileResult& result, const PagedBenchConfig& config);
// One JSON record per row, with the files' summaries; rf::Error when the file cannot be written.
void write_paged_json(const std::string& path, const std::vector<PagedFileResult>& results,
                      const PagedBenchConfig& config, const std::string& command);

}  // namespace rf::bench
