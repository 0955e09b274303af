// make_grid_accel: the uniform grid built and wrapped as an rf::Accel.
#include "accel/grid/grid_accel.h"

#include <chrono>
#include <limits>
#include <string>

#include "accel/accel_factories.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {

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
    AccelStats stats;
    stats.name = std::move(name);
    stats.build_ms = build_ms;
    return std::make_unique<GridAccel>(
        std::move(grid), [&](const UniformGrid& g) { return GridTracer{g.view(geometry.triangles.data())}; },
        std::move(stats));
}

void describe_structure(const UniformGrid& grid, AccelStats& s) {
    s.node_count = grid.cell_count();
    s.leaf_count = grid.non_empty_cells();
    s.bytes = grid.memory_bytes();
    s.sah_cost = std::numeric_limits<double>::quiet_NaN();
    s.quality_cost = std::numeric_limits<double>::quiet_NaN();
}

}  // namespace rf
