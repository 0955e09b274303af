#include "ooc/top_grid.h"

#include <algorithm>
#include <cmath>

#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::pack {

namespace {

struct CellEntry {
    uint32_t cell;
    uint32_t ref;
    Box3f clipped;
};

Box3f intersect(const Box3f& a, const Box3f& b) {
    return {max(a.lo, b.lo), min(a.hi, b.hi)};
}

// One cell's BVH over its clipped page boxes (binned SAH, one page per leaf).
std::vector<BvhNode> cell_bvh(std::span<const CellEntry> entries) {
    std::vector<Triangle> boxes(entries.size());
    for (size_t i = 0; i < entries.size(); ++i) {
        const Box3f& b = entries[i].clipped;
        boxes[i] = {b.lo, b.hi, (b.lo + b.hi) * 0.5f};
    }
    BuildOptions options;
    options.builder = Builder::BinnedSah;
    options.max_leaf_size = 1;
    const Bvh bvh = build_bvh(boxes, options);
    std::vector<BvhNode> nodes = bvh.nodes;
    for (BvhNode& n : nodes)
        if (n.is_leaf()) n.first = entries[bvh.prim_indices[n.first]].ref;
    return nodes;
}

}  // namespace

void grid_resolution_for(const Box3f& box, int cells_on_longest, int out[3]) {
    const Vec3f extent = box.hi - box.lo;
    const float longest = std::max(extent.x, std::max(extent.y, extent.z));
    for (int a = 0; a < 3; ++a)
        out[a] = longest > 0.0f ? std::clamp(int(std::lround(float(cells_on_longest) * extent[a] / longest)), 1,
                                             cells_on_longest)
                                : 1;
}

TopGrid build_top_grid(std::span<const Box3f> ref_boxes, int cells_on_longest) {
    TopGrid grid;
    for (const Box3f& b : ref_boxes) grid.scene_bounds.extend(b);
    if (ref_boxes.empty()) {
        grid.scene_bounds = grid.grid_bounds = Box3f{Vec3f(0.0f), Vec3f(0.0f)};
        grid.cell_roots.assign(1, kEmptyCell);
        return grid;
    }
    const Vec3f extent = grid.scene_bounds.hi - grid.scene_bounds.lo;
    const float pad = std::max(extent.x, std::max(extent.y, extent.z)) * 1e-4f + 1e-20f;
    grid.grid_bounds = {grid.scene_bounds.lo - Vec3f(pad), grid.scene_bounds.hi + Vec3f(pad)};
    grid_resolution_for(grid.grid_bounds, cells_on_longest, grid.resolution);
    const int* res = grid.resolution;
    const Vec3f lo = grid.grid_bounds.lo;
    const Vec3f cell = (grid.grid_bounds.hi - lo) / Vec3f(float(res[0]), float(res[1]), float(res[2]));
    const auto cell_of = [&](float v, int a) { return std::clamp(int(std::floor((v - lo[a]) / cell[a])), 0, res[a] - 1); };

    // A page within rounding of a cell boundary goes into the cells on both
    // sides, so a ray the DDA steps past a corner by rounding still meets it.
    const Vec3f margin = cell * 1e-3f;
    std::vector<CellEntry> entries;
    for (uint32_t ref = 0; ref < ref_boxes.size(); ++ref) {
        const Box3f& b = ref_boxes[ref];
        int c0[3], c1[3];
        for (int a = 0; a < 3; ++a) {
            c0[a] = cell_of(b.lo[a] - margin[a], a);
            c1[a] = cell_of(b.hi[a] + margin[a], a);
        }
        for (int z = c0[2]; z <= c1[2]; ++z)
            for (int y = c0[1]; y <= c1[1]; ++y)
                for (int x = c0[0]; x <= c1[0]; ++x) {
                    const Vec3f cell_lo = lo + cell * Vec3f(float(x), float(y), float(z));
                    const Box3f cell_box{cell_lo - margin, cell_lo + cell + margin};
                    const Box3f clipped = intersect(b, cell_box);
                    if (clipped.is_empty()) continue;
                    entries.push_back({uint32_t((z * res[1] + y) * res[0] + x), ref, clipped});
                }
    }
    std::stable_sort(entries.begin(), entries.end(), [](const CellEntry& a, const CellEntry& b) { return a.cell < b.cell; });

    const size_t cells = size_t(res[0]) * size_t(res[1]) * size_t(res[2]);
    std::vector<std::pair<size_t, size_t>> ranges;  // per non-empty cell, in cell order
    for (size_t i = 0; i < entries.size();) {
        size_t j = i;
        while (j < entries.size() && entries[j].cell == entries[i].cell) ++j;
        ranges.emplace_back(i, j);
        i = j;
    }
    std::vector<std::vector<BvhNode>> trees(ranges.size());
    parallel::for_each_index(size_t(0), ranges.size(), [&](size_t k) {
        trees[k] = cell_bvh(std::span<const CellEntry>(entries).subspan(ranges[k].first, ranges[k].second - ranges[k].first));
    });
    grid.cell_roots.assign(cells, kEmptyCell);
    for (size_t k = 0; k < ranges.size(); ++k) {
        const uint32_t base = uint32_t(grid.middle_nodes.size());
        grid.cell_roots[entries[ranges[k].first].cell] = base;
        for (BvhNode n : trees[k]) {
            if (!n.is_leaf()) n.first += base;
            grid.middle_nodes.push_back(n);
        }
    }
    return grid;
}

}  // namespace rf::pack
