// make_grid_accel and the batched queries of the uniform grid (seeds 001, 002).
#include "backend/cpu/ray_batches.h"
#include "accel/grid/grid_accel.h"

#include <chrono>
#include <limits>
#include <string>

#include "accel/accel_factories.h"
#include "backend/cpu/parallel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {



}  // namespace

std::unique_ptr<Accel> make_grid_accel(const SceneGeometry& geometry, const BuildOptions& options) {
    if (options.structure != Structure::Grid && options.structure != Structure::ProximityGrid) {
        throw Error("make_grid_accel: structure must be grid or grid-proximity, got " + to_string(options.structure));
    }
    if (options.grid.resolution < 0 || options.grid.resolution > 2048) {
        throw Error("build options: grid.resolution must be in [0, 2048] (0 = automatic), got " +
                    std::to_string(options.grid.resolution));
    }
    if (options.threads < 0) {
        throw Error("build options: threads must be >= 0 (0 = all cores), got " + std::to_string(options.threads));
    }
    const bool proximity = options.structure == Structure::ProximityGrid;
    const auto start = std::chrono::steady_clock::now();
    UniformGrid grid = parallel::with_threads(options.threads, [&] {
        return build_uniform_grid(geometry.triangles, options.grid.resolution, proximity);
    });
    const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    const auto& dims = grid.layout.dims;
    std::string name = to_string(options.structure) + "/" + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) +
                       "x" + std::to_string(dims[2]);
    return std::make_unique<GridAccel>(geometry, std::move(grid), std::move(name), build_ms);
}

AccelStats GridAccel::stats() const {
    AccelStats s;
    s.name = name_;
    s.build_ms = build_ms_;
    s.node_count = grid_.cell_count();
    s.leaf_count = grid_.non_empty_cells();
    s.bytes = grid_.memory_bytes();
    s.sah_cost = std::numeric_limits<double>::quiet_NaN();
    s.quality_cost = std::numeric_limits<double>::quiet_NaN();
    return s;
}

void GridAccel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    check_batch_sizes("GridAccel::intersect", rays.size(), hits.size());
    const GridView grid = view();
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) hits[i] = grid_intersect(grid, rays[i]);
    });
}

void GridAccel::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    check_batch_sizes("GridAccel::occluded", rays.size(), occluded.size());
    const GridView grid = view();
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) occluded[i] = grid_occluded(grid, rays[i]) ? 1 : 0;
    });
}

bool GridAccel::count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const {
    const GridView grid = view();
    totals += sum_traversal_counts(rays, [&](const Ray& ray, TraversalTotals& acc) {
        GridTraversalCounters counters;
        if (any_hit) (void)grid_occluded_counted(grid, ray, counters);
        else (void)grid_intersect_counted(grid, ray, counters);
        acc.steps += counters.cells_visited;
        acc.prim_tests += counters.prims_tested;
    });
    return true;
}

}  // namespace rf
