// The per-thread logic of the CUDA uniform grid (Kalojanov and Slusallek
// 2009; src/accel/grid/uniform_grid_steps.h, run by backend/cuda/
// uniform_grid_build.cu) run on the CPU the way the kernels run it: a
// "thread" per triangle counts its cells, an exclusive scan gives the write
// offsets, the threads write their (cell, triangle) pairs, an LSD radix sort
// of 8-bit digits over cell_key_bits() bits (what CUB does) orders them, a
// thread per sorted pair marks the cell starts, and the distance transform
// runs its three passes a thread per cell; threads run in shuffled orders.
// The result must equal build_uniform_grid's grid (offsets, lists,
// proximity bytes) on ordinary, flat, thin and degenerate scenes with
// automatic and given resolutions; the 1D pass must equal the CPU's
// Chebyshev transform, saturated, on random and far-apart occupancies.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel/grid/proximity_clouds.h"
#include "accel/grid/uniform_grid.h"
#include "accel/grid/uniform_grid_steps.h"
#include "accel_test_scenes.h"

namespace rf {
namespace {

namespace steps = uniform_grid_steps;

constexpr uint32_t kUnset = 0xdeadbeefu;

std::vector<uint32_t> shuffled(size_t n, uint32_t seed) {
    std::vector<uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    std::mt19937 rng(seed);
    std::shuffle(order.begin(), order.end(), rng);
    return order;
}

// CUB's LSD radix sort of (key, value) over the low `bits` bits: stable
// counting sorts of 8-bit digits, the last one narrower.
void radix_sort_pairs(std::vector<uint32_t>& keys, std::vector<uint32_t>& values, int bits) {
    std::vector<uint32_t> k2(keys.size()), v2(values.size());
    for (int shift = 0; shift < bits; shift += 8) {
        const int width = std::min(8, bits - shift);
        const uint32_t mask = (1u << width) - 1u;
        std::vector<size_t> start((size_t{1} << width) + 1, 0);
        for (uint32_t k : keys) ++start[((k >> shift) & mask) + 1];
        for (size_t d = 1; d < start.size(); ++d) start[d] += start[d - 1];
        for (size_t i = 0; i < keys.size(); ++i) {
            const size_t slot = start[(keys[i] >> shift) & mask]++;
            k2[slot] = keys[i];
            v2[slot] = values[i];
        }
        keys.swap(k2);
        values.swap(v2);
    }
}

// Three passes of the device's distance transform, a thread per cell.
std::vector<uint8_t> device_distance_transform(const std::vector<uint8_t>& initial, std::array<int, 3> dims,
                                               uint32_t seed) {
    std::vector<uint8_t> in = initial, out(initial.size(), 0xAB);
    for (int axis = 0; axis < 3; ++axis) {
        for (uint32_t c : shuffled(in.size(), seed + axis)) out[c] = steps::chessboard_pass_at(in.data(), dims.data(), axis, c);
        in.swap(out);
    }
    return in;
}

// The device build, stage by stage, on the CPU.
UniformGrid emulate_device_build(std::span<const Triangle> triangles, int resolution, bool proximity, uint32_t seed) {
    UniformGrid grid;
    Box3f bounds;
    for (const Triangle& t : triangles) bounds.extend(t.bounds());
    grid.layout = choose_grid_layout(bounds, triangles.size(), resolution);
    const uint64_t cells = grid.layout.cell_count();
    if (cells == 0) return grid;
    grid.inflation = steps::cell_inflation(grid.layout);
    const steps::CellPlanes planes(grid.layout);
    const steps::CellGridView view = planes.view(grid.layout, grid.inflation, planes.values.data());
    const uint32_t n = static_cast<uint32_t>(triangles.size());

    // 1-3. Count, exclusive scan, write.
    std::vector<uint64_t> counts(n, kUnset), offsets(n);
    for (uint32_t t : shuffled(n, seed)) counts[t] = steps::count_overlapped_cells(view, triangles[t]);
    uint64_t total = 0;
    for (uint32_t t = 0; t < n; ++t) offsets[t] = total, total += counts[t];
    EXPECT_LE(total, uint64_t{0xffffffffu});
    const uint32_t pairs = static_cast<uint32_t>(total);
    std::vector<uint32_t> pair_cells(pairs, kUnset), pair_triangles(pairs, kUnset);
    for (uint32_t t : shuffled(n, seed + 1)) {
        steps::write_cell_pairs(view, triangles[t], t, static_cast<uint32_t>(offsets[t]), pair_cells.data(),
                                pair_triangles.data());
    }
    // 4. The sort.
    radix_sort_pairs(pair_cells, pair_triangles, steps::cell_key_bits(cells));
    // 5. Cell ranges.
    grid.cell_start.assign(cells + 1, kUnset);
    if (pairs == 0) {
        std::fill(grid.cell_start.begin(), grid.cell_start.end(), 0u);
    } else {
        for (uint32_t c : shuffled(uint32_t(cells + 1), seed + 2))
            grid.cell_start[c] = steps::cell_start_of(pair_cells.data(), pairs, c);
    }
    grid.cell_prims = std::move(pair_triangles);
    // 6. Proximity clouds.
    if (proximity) {
        std::vector<uint8_t> initial(cells);
        for (uint64_t c = 0; c < cells; ++c) initial[c] = steps::occupancy_distance(grid.cell_start.data(), c);
        grid.proximity = device_distance_transform(initial, grid.layout.dims, seed + 3);
    }
    return grid;
}

void expect_same_grid(const UniformGrid& expected, const UniformGrid& got, const std::string& what) {
    EXPECT_EQ(expected.layout.dims, got.layout.dims) << what;
    EXPECT_EQ(std::memcmp(&expected.layout.origin, &got.layout.origin, sizeof(Vec3f)), 0) << what;
    EXPECT_EQ(expected.layout.cell_size, got.layout.cell_size) << what;
    EXPECT_EQ(expected.inflation, got.inflation) << what;
    EXPECT_EQ(expected.cell_start, got.cell_start) << what;
    EXPECT_EQ(expected.cell_prims, got.cell_prims) << what;
    EXPECT_EQ(expected.proximity, got.proximity) << what;
}

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(5000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"big triangles", test::make_triangle_soup(200, 2, {Vec3f(-10.0f), Vec3f(10.0f)}, 8.0f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(3))});
    scenes.push_back({"cube", test::to_geometry(test::make_tessellated_cube(8))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    scenes.push_back({"far", test::make_triangle_soup(1000, 3, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    SceneGeometry flat;  // one plane, z = 1
    for (int i = 0; i < 600; ++i) {
        const float x = float(i % 30) * 0.2f, y = float(i / 30) * 0.2f;
        test::append(flat, {Vec3f(x, y, 1.0f), Vec3f(x + 0.3f, y, 1.0f), Vec3f(x, y + 0.3f, 1.0f)});
    }
    scenes.push_back({"flat", std::move(flat)});
    SceneGeometry thin;  // a long thin strip along x
    for (int i = 0; i < 400; ++i) {
        const float x = float(i) * 0.1f;
        test::append(thin, {Vec3f(x, 0, 0), Vec3f(x + 0.15f, 0.01f, 0), Vec3f(x, 0, 0.01f)});
    }
    scenes.push_back({"thin", std::move(thin)});
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    scenes.push_back({"one triangle", std::move(one)});
    SceneGeometry point;
    for (int i = 0; i < 100; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    scenes.push_back({"one point", std::move(point)});
    scenes.push_back({"empty", SceneGeometry{}});
    return scenes;
}

TEST(UniformGridDeviceLogic, PairPipelineEqualsCpuGrid) {
    uint32_t seed = 1;
    for (const NamedScene& scene : test_scenes()) {
        for (int resolution : {0, 1, 5, 32}) {
            for (bool proximity : {false, true}) {
                const std::string what = scene.name + ", resolution " + std::to_string(resolution) +
                                         (proximity ? ", proximity clouds" : "");
                const UniformGrid cpu = build_uniform_grid(scene.geometry.triangles, resolution, proximity);
                expect_same_grid(cpu, emulate_device_build(scene.geometry.triangles, resolution, proximity, ++seed),
                                 what);
            }
        }
    }
}

TEST(UniformGridDeviceLogic, SharedCellWalkMatchesBoxSearch) {
    // Independent of the column walk: every cell of the triangle's bounds
    // range tested with the SAT, against the cells the walk reports.
    const SceneGeometry scene = test::make_triangle_soup(300, 9, {Vec3f(-10.0f), Vec3f(10.0f)}, 6.0f);
    Box3f bounds;
    for (const Triangle& t : scene.triangles) bounds.extend(t.bounds());
    const GridLayout layout = choose_grid_layout(bounds, scene.triangles.size(), 24);
    const double eps = steps::cell_inflation(layout);
    const steps::CellPlanes planes(layout);
    const steps::CellGridView view = planes.view(layout, eps, planes.values.data());
    size_t total = 0;
    for (const Triangle& t : scene.triangles) {
        std::vector<uint32_t> walked;
        steps::for_each_overlapped_cell(view, t, [&](uint32_t c) { walked.push_back(c); });
        std::sort(walked.begin(), walked.end());
        EXPECT_TRUE(std::adjacent_find(walked.begin(), walked.end()) == walked.end()) << "a cell visited twice";
        std::vector<uint32_t> searched;
        const steps::Vec3d v0 = steps::to_vec3d(t.v0), v1 = steps::to_vec3d(t.v1), v2 = steps::to_vec3d(t.v2);
        for (int z = 0; z < layout.dims[2]; ++z)
            for (int y = 0; y < layout.dims[1]; ++y)
                for (int x = 0; x < layout.dims[0]; ++x)
                    if (steps::overlaps_cell(view, v0, v1, v2, x, y, z)) searched.push_back(steps::cell_index(view, x, y, z));
        EXPECT_EQ(walked, searched);
        total += walked.size();
    }
    EXPECT_GT(total, scene.triangles.size() * 8);  // big triangles: the column walk ran
}

TEST(UniformGridDeviceLogic, DistancePassesEqualCpuTransformSaturated) {
    std::mt19937 rng(7);
    const std::vector<std::array<int, 3>> shapes = {{1, 1, 1}, {7, 5, 3}, {16, 16, 16}, {300, 2, 1},
                                                    {1, 1, 600}, {3, 520, 2}, {40, 1, 33}};
    for (const std::array<int, 3>& dims : shapes) {
        for (double fill : {0.0, 0.002, 0.05, 0.5}) {
            const size_t cells = size_t(dims[0]) * dims[1] * dims[2];
            std::vector<uint8_t> occupied(cells, 0);
            std::bernoulli_distribution coin(fill);
            for (auto& o : occupied) o = coin(rng) ? 1 : 0;
            if (fill > 0.0 && cells > 1) occupied[cells - 1] = 1;  // far from the first cell on long lines
            const std::vector<uint32_t> exact = chebyshev_distance_transform(occupied, dims);
            std::vector<uint8_t> initial(cells);
            for (size_t c = 0; c < cells; ++c) initial[c] = occupied[c] ? 0 : uint8_t(steps::kProximityCap);
            const std::vector<uint8_t> got = device_distance_transform(initial, dims, 11);
            size_t wrong = 0;
            for (size_t c = 0; c < cells; ++c) wrong += got[c] != std::min<uint32_t>(exact[c], 255);
            EXPECT_EQ(wrong, 0u) << dims[0] << "x" << dims[1] << "x" << dims[2] << ", fill " << fill;
        }
    }
}

TEST(UniformGridDeviceLogic, CellKeyBitsCoverTheLargestCell) {
    EXPECT_EQ(steps::cell_key_bits(1), 1);
    EXPECT_EQ(steps::cell_key_bits(2), 1);
    EXPECT_EQ(steps::cell_key_bits(3), 2);
    EXPECT_EQ(steps::cell_key_bits(256), 8);
    EXPECT_EQ(steps::cell_key_bits(257), 9);
    EXPECT_EQ(steps::cell_key_bits(4294967294ull), 32);
    for (uint64_t cells : {5ull, 1000ull, 123457ull}) {
        EXPECT_LT(cells - 1, uint64_t{1} << steps::cell_key_bits(cells));
    }
}

TEST(UniformGridDeviceLogic, CellStartsFollowTheCpuConvention) {
    // Cells 0..7: references in cells 2 (x2), 3 and 6; 0, 1, 4, 5 and 7 empty.
    const std::vector<uint32_t> sorted = {2, 2, 3, 6};
    std::vector<uint32_t> start(9, kUnset);
    for (uint32_t c : {3u, 8u, 0u, 2u, 7u, 1u, 5u, 6u, 4u}) start[c] = steps::cell_start_of(sorted.data(), 4, c);
    EXPECT_EQ(start, (std::vector<uint32_t>{0, 0, 0, 2, 3, 3, 3, 4, 4}));
}

TEST(UniformGridDeviceLogic, CellStartsAreThePrefixSumOfCellCounts) {
    std::mt19937 rng(5);
    for (uint32_t cells : {1u, 2u, 17u, 1000u}) {
        for (uint32_t pairs : {1u, 3u, 200u}) {
            std::uniform_int_distribution<uint32_t> pick(0, cells - 1);
            std::vector<uint32_t> sorted(pairs);
            for (uint32_t& c : sorted) c = pick(rng);
            std::sort(sorted.begin(), sorted.end());
            std::vector<uint32_t> start(cells + 1, kUnset);
            for (uint32_t c : shuffled(cells + 1, cells + pairs)) start[c] = steps::cell_start_of(sorted.data(), pairs, c);
            // The expected offsets: references in the cells before c.
            std::vector<uint32_t> expected(cells + 1, 0);
            for (uint32_t c : sorted) ++expected[c + 1];
            for (size_t c = 1; c <= cells; ++c) expected[c] += expected[c - 1];
            EXPECT_EQ(start, expected) << cells << " cells, " << pairs << " pairs";
        }
    }
}

}  // namespace
}  // namespace rf
