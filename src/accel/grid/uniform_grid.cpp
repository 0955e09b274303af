// Uniform grid build (Bogolepov et al., §2.1.2; Zlatuška 2009, §4.2.1): layout
// by Zlatuška 2009's resolution rule, exact triangle/cell overlap by
// Akenine-Möller's SAT test (Bogolepov et al.), compact per-cell lists built
// in parallel by a count pass, a prefix sum and a fill pass. The
// per-triangle cell enumeration lives in uniform_grid_steps.h, shared with the
// sort-based device build.
#include "accel/grid/uniform_grid.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <string>

#include "accel/grid/proximity_clouds.h"
#include "accel/grid/uniform_grid_steps.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

constexpr size_t kTriangleGrain = 256;
constexpr size_t kCellGrain = size_t(1) << 14;
// The largest cell count: indices and the +1 offset stay 32-bit.
constexpr double kMaxCells = 4294967294.0;
// Zlatuška 2009's rule, capped at this many times the cells of a cubic scene.
constexpr double kAutoCellFactor = 8.0;

double max_abs_coordinate(const Box3f& b) {
    double m = 0.0;
    for (int a = 0; a < 3; ++a) m = std::max({m, std::fabs(double(b.lo[a])), std::fabs(double(b.hi[a]))});
    return m;
}

// Cells per axis for cubic cells of size s over padded extents.
std::array<double, 3> cells_for(const double (&padded)[3], double s) {
    std::array<double, 3> d{};
    for (int a = 0; a < 3; ++a) d[a] = std::max(1.0, std::ceil(padded[a] / s - 1e-6));
    return d;
}

}  // namespace

GridLayout choose_grid_layout(const Box3f& bounds, size_t triangle_count, int resolution) {
    GridLayout layout;
    if (triangle_count == 0 || bounds.is_empty()) return layout;
    if (!is_finite(bounds.lo) || !is_finite(bounds.hi)) throw Error("uniform grid: scene bounds are not finite");
    if (resolution < 0) throw Error("uniform grid: resolution must be >= 0, got " + std::to_string(resolution));

    double extent[3], padded[3];
    double max_extent = 0.0;
    for (int a = 0; a < 3; ++a) {
        extent[a] = double(bounds.hi[a]) - double(bounds.lo[a]);
        max_extent = std::max(max_extent, extent[a]);
    }
    const double magnitude = max_abs_coordinate(bounds);
    // Geometry stays strictly inside the grid box: rays grazing the box miss it.
    const double margin = max_extent * 1e-5 + magnitude * 0x1p-20;
    double max_padded = 0.0;
    for (int a = 0; a < 3; ++a) {
        padded[a] = extent[a] + 2.0 * margin;
        max_padded = std::max(max_padded, padded[a]);
    }

    double s = 0.0;
    double auto_cap = 0.0;
    if (resolution > 0) {
        s = max_padded / resolution;
    } else {
        const double r = std::max(1.0, std::floor(4.0 * std::pow(double(triangle_count), 0.25)));
        double shortest = 0.0;
        for (int a = 0; a < 3; ++a) {
            if (extent[a] > 0.0 && (shortest == 0.0 || padded[a] < shortest)) shortest = padded[a];
        }
        s = shortest / r;
        auto_cap = std::max(kAutoCellFactor * r * r * r, 64.0);
    }
    // Cells at least a few ulps of the coordinates wide, so that consecutive
    // float boundaries stay distinct; a point-like scene gets one cell.
    s = std::max(s, magnitude * 0x1p-21);
    if (!(s > 0.0)) s = 1.0;

    std::array<double, 3> dims = cells_for(padded, s);
    if (auto_cap > 0.0) {
        for (int i = 0; i < 64 && dims[0] * dims[1] * dims[2] > auto_cap; ++i) {
            s *= std::cbrt(dims[0] * dims[1] * dims[2] / auto_cap) * 1.001;
            dims = cells_for(padded, s);
        }
    }
    const double cells = dims[0] * dims[1] * dims[2];
    if (cells > kMaxCells) {
        throw Error("uniform grid: " + std::to_string(dims[0]) + " x " + std::to_string(dims[1]) + " x " +
                    std::to_string(dims[2]) + " cells exceed 32-bit cell indices (resolution " +
                    std::to_string(resolution) + ")");
    }

    layout.cell_size = static_cast<float>(s);
    for (int a = 0; a < 3; ++a) {
        layout.dims[a] = static_cast<int>(dims[a]);
        const double center = 0.5 * (double(bounds.lo[a]) + double(bounds.hi[a]));
        float origin = static_cast<float>(center - 0.5 * dims[a] * s);
        // Rounding to float must not leave geometry outside the grid box.
        const auto plane = [&](int i) { return origin + static_cast<float>(i) * layout.cell_size; };
        while (!(plane(0) <= bounds.lo[a])) origin = std::nextafter(origin, -std::numeric_limits<float>::infinity());
        while (!(plane(layout.dims[a]) >= bounds.hi[a])) ++layout.dims[a];
        layout.origin[a] = origin;
    }
    if (double(layout.dims[0]) * layout.dims[1] * layout.dims[2] > kMaxCells) {
        throw Error("uniform grid: too many cells for 32-bit cell indices (resolution " + std::to_string(resolution) +
                    ")");
    }
    return layout;
}

namespace {

// Inclusive prefix sum of the per-cell counts in place, in parallel blocks;
// returns the total. Throws when it does not fit 32-bit offsets.
uint64_t inclusive_scan(std::vector<uint32_t>& counts, size_t n) {
    const size_t block = std::max<size_t>(kCellGrain, (n + 255) / 256);
    const size_t blocks = (n + block - 1) / block;
    std::vector<uint64_t> sums(blocks, 0);
    parallel::for_range(size_t(0), blocks, size_t(1), [&](size_t lo, size_t hi) {
        for (size_t b = lo; b < hi; ++b) {
            uint64_t s = 0;
            for (size_t i = b * block, end = std::min(n, (b + 1) * block); i < end; ++i) s += counts[i];
            sums[b] = s;
        }
    });
    uint64_t total = 0;
    for (uint64_t& s : sums) {
        const uint64_t block_sum = s;
        s = total;  // exclusive: the block's offset
        total += block_sum;
    }
    if (total > std::numeric_limits<uint32_t>::max()) {
        throw Error("uniform grid: " + std::to_string(total) + " cell references exceed 32-bit offsets");
    }
    parallel::for_range(size_t(0), blocks, size_t(1), [&](size_t lo, size_t hi) {
        for (size_t b = lo; b < hi; ++b) {
            uint64_t s = sums[b];
            for (size_t i = b * block, end = std::min(n, (b + 1) * block); i < end; ++i) {
                s += counts[i];
                counts[i] = static_cast<uint32_t>(s);
            }
        }
    });
    return total;
}

Box3f triangle_bounds(std::span<const Triangle> triangles) {
    return parallel::reduce(
        size_t(0), triangles.size(), size_t(4096), Box3f{},
        [&](size_t lo, size_t hi, Box3f acc) {
            for (size_t i = lo; i < hi; ++i) acc.extend(triangles[i].bounds());
            return acc;
        },
        [](Box3f a, const Box3f& b) { return merge(a, b); });
}

}  // namespace

namespace uniform_grid_steps {

// Margin on every cell, larger than the traversal's rounding: its crossing
// distances are off by a few ulps of the grid's size and its positions by a
// few ulps of the coordinates. The triangle test, though, computes in the
// frame of the ray's origin, so its hits can be off the triangle by a few
// ulps of the origin's distance: 2^-15 of the grid's size covers origins up
// to ~50 grid sizes away (beyond that, a hit within rounding of a silhouette
// edge, an artefact of that rounding, can be missed).
double cell_inflation(const GridLayout& layout) {
    const GridView shape{nullptr, nullptr, nullptr, nullptr, layout.origin, layout.cell_size, 0.0f, {0, 0, 0}};
    Box3f grid_box;
    for (int a = 0; a < 3; ++a) {
        grid_box.lo[a] = grid_plane(shape, a, 0);
        grid_box.hi[a] = grid_plane(shape, a, layout.dims[a]);
    }
    return 1e-4 * layout.cell_size + double(max_component(grid_box.extent())) * 0x1p-15 +
           max_abs_coordinate(grid_box) * 0x1p-22;
}

CellPlanes::CellPlanes(const GridLayout& layout) {
    const GridView shape{nullptr, nullptr, nullptr, nullptr, layout.origin, layout.cell_size, 0.0f, {0, 0, 0}};
    budgeted_reserve(values, size_t(layout.dims[0]) + layout.dims[1] + layout.dims[2] + 3, "uniform grid: cell planes");
    for (int a = 0; a < 3; ++a) {
        offset[a] = values.size();
        for (int i = 0; i <= layout.dims[a]; ++i) values.push_back(double(grid_plane(shape, a, i)));
    }
}

}  // namespace uniform_grid_steps

UniformGrid build_uniform_grid(std::span<const Triangle> triangles, int resolution, bool proximity_clouds) {
    UniformGrid grid;
    if (triangles.size() > std::numeric_limits<uint32_t>::max() - 1) {
        throw Error("uniform grid: " + std::to_string(triangles.size()) + " triangles exceed 32-bit indices");
    }
    const Box3f bounds = triangle_bounds(triangles);
    grid.layout = choose_grid_layout(bounds, triangles.size(), resolution);
    const size_t cells = grid.layout.cell_count();
    if (cells == 0) return grid;

    // The margin on every cell and the cells' planes (uniform_grid_steps.h,
    // shared with the device build so that both fill the same cells).
    grid.inflation = uniform_grid_steps::cell_inflation(grid.layout);
    const uniform_grid_steps::CellPlanes planes(grid.layout);
    const uniform_grid_steps::CellGridView overlap = planes.view(grid.layout, grid.inflation, planes.values.data());

    // Count pass: references per cell.
    budgeted_resize(grid.cell_start, cells + 1, "uniform grid: cell offsets");
    uint32_t* start = grid.cell_start.data();
    parallel::for_range(size_t(0), triangles.size(), kTriangleGrain, [&](size_t lo, size_t hi) {
        for (size_t t = lo; t < hi; ++t) {
            uniform_grid_steps::for_each_overlapped_cell(overlap, triangles[t], [&](uint32_t cell) {
                std::atomic_ref<uint32_t>(start[cell]).fetch_add(1, std::memory_order_relaxed);
            });
        }
    });
    // Prefix sum: start[c] = end of cell c's list, until the fill pass moves it to its beginning.
    const uint64_t references = inclusive_scan(grid.cell_start, cells);
    grid.cell_start[cells] = static_cast<uint32_t>(references);
    budgeted_resize(grid.cell_prims, static_cast<size_t>(references), "uniform grid: cell references");

    // Fill pass: each reference claims the slot below its cell's cursor.
    uint32_t* prims = grid.cell_prims.data();
    parallel::for_range(size_t(0), triangles.size(), kTriangleGrain, [&](size_t lo, size_t hi) {
        for (size_t t = lo; t < hi; ++t) {
            uniform_grid_steps::for_each_overlapped_cell(overlap, triangles[t], [&](uint32_t cell) {
                const uint32_t slot = std::atomic_ref<uint32_t>(start[cell]).fetch_sub(1, std::memory_order_relaxed) - 1;
                prims[slot] = static_cast<uint32_t>(t);
            });
        }
    });
    // The fill order depends on thread timing: sort each list so that the
    // grid (and so the choice among tied hits) is deterministic.
    parallel::for_range(size_t(0), cells, kCellGrain, [&](size_t lo, size_t hi) {
        for (size_t c = lo; c < hi; ++c) {
            if (start[c + 1] - start[c] > 1) std::sort(prims + start[c], prims + start[c + 1]);
        }
    });

    if (proximity_clouds) {
        std::vector<uint8_t> occupied;
        budgeted_resize(occupied, cells, "uniform grid: occupancy");
        parallel::for_range(size_t(0), cells, kCellGrain, [&](size_t lo, size_t hi) {
            for (size_t c = lo; c < hi; ++c) occupied[c] = start[c + 1] > start[c] ? 1 : 0;
        });
        const std::vector<uint32_t> distance = chebyshev_distance_transform(occupied, grid.layout.dims);
        // Saturating is safe: a smaller distance only skips less.
        grid.proximity = std::move(occupied);
        parallel::for_range(size_t(0), cells, kCellGrain, [&](size_t lo, size_t hi) {
            for (size_t c = lo; c < hi; ++c) grid.proximity[c] = static_cast<uint8_t>(std::min<uint32_t>(distance[c], 255));
        });
    }
    return grid;
}

size_t UniformGrid::non_empty_cells() const {
    size_t count = 0;
    for (size_t c = 0; c + 1 < cell_start.size(); ++c) count += cell_start[c + 1] > cell_start[c];
    return count;
}

size_t UniformGrid::memory_bytes() const {
    return cell_start.size() * sizeof(uint32_t) + cell_prims.size() * sizeof(uint32_t) +
           proximity.size() * sizeof(uint8_t);
}

Box3f UniformGrid::cell_box(int x, int y, int z) const {
    const GridView v = view(nullptr);
    Box3f b;
    const int c[3] = {x, y, z};
    for (int a = 0; a < 3; ++a) {
        b.lo[a] = grid_plane(v, a, c[a]);
        b.hi[a] = grid_plane(v, a, c[a] + 1);
    }
    return b;
}

GridView UniformGrid::view(const Triangle* triangles) const {
    GridView v;
    v.cell_start = cell_start.data();
    v.cell_prims = cell_prims.data();
    v.proximity = proximity.empty() ? nullptr : proximity.data();
    v.triangles = triangles;
    v.origin = layout.origin;
    v.cell_size = layout.cell_size;
    v.inv_cell_size = layout.cell_size > 0.0f ? 1.0f / layout.cell_size : 0.0f;
    // The layout's dims describe the cells even before the lists exist; an
    // empty grid (no cells) has dims 0.
    for (int a = 0; a < 3; ++a) v.dims[a] = layout.dims[a];
    return v;
}

}  // namespace rf
