// The CUDA uniform grid (Kalojanov and Slusallek 2009; backend/cuda/
// uniform_grid_build.cu) against the CPU grid (uniform_grid.cpp): the same
// layout, margin, cell offsets, cell lists (ascending triangles) and
// proximity bytes on soups, a sphere, flat and thin scenes, degenerate
// inputs, automatic and given resolutions; stages and peak memory reported;
// the host memory budget and the 32-bit reference limit give rf::Error.
// Skips with a message when no CUDA device is present.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <vector>

#include "../accel_test_scenes.h"
#include "accel/grid/uniform_grid.h"
#include "gpu_build_checks.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using gpu_build_test::append_degenerate_scenes;
using gpu_build_test::NamedScene;

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(20000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"big triangles", test::make_triangle_soup(500, 2, {Vec3f(-10.0f), Vec3f(10.0f)}, 8.0f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(5))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    scenes.push_back({"far", test::make_triangle_soup(3000, 3, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    scenes.push_back({"flat", test::make_triangle_soup(2000, 4, {Vec3f(-5, -5, 0), Vec3f(5, 5, 0)}, 0.3f)});
    SceneGeometry flat;
    for (int i = 0; i < 2000; ++i) {
        const float x = float(i % 50) * 0.2f, y = float(i / 50) * 0.2f;
        test::append(flat, {Vec3f(x, y, 1.0f), Vec3f(x + 0.3f, y, 1.0f), Vec3f(x, y + 0.3f, 1.0f)});
    }
    scenes.push_back({"plane z=1", std::move(flat)});
    SceneGeometry thin;
    for (int i = 0; i < 1000; ++i) {
        const float x = float(i) * 0.1f;
        test::append(thin, {Vec3f(x, 0, 0), Vec3f(x + 0.15f, 0.01f, 0), Vec3f(x, 0, 0.01f)});
    }
    scenes.push_back({"thin", std::move(thin)});
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    scenes.push_back({"one", std::move(one)});
    append_degenerate_scenes(scenes);
    return scenes;
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

TEST(GpuUniformGridBuild, SameGridAsCpu) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        for (int resolution : {0, 1, 9, 64}) {
            for (bool proximity : {false, true}) {
                const std::string what = scene.name + ", resolution " + std::to_string(resolution) +
                                         (proximity ? ", proximity clouds" : "");
                expect_same_grid(build_uniform_grid(scene.geometry.triangles, resolution, proximity),
                                 cuda::build_uniform_grid_on_device(scene.geometry.triangles, resolution, proximity),
                                 what);
            }
        }
    }
}

TEST(GpuUniformGridBuild, EmptyInput) {
    RF_REQUIRE_DEVICE();
    cuda::DeviceBuildStages stages;
    const UniformGrid grid = cuda::build_uniform_grid_on_device({}, 0, true, &stages);
    EXPECT_EQ(grid.cell_count(), 0u);
    EXPECT_TRUE(grid.cell_start.empty());
    EXPECT_TRUE(grid.cell_prims.empty());
    EXPECT_EQ(stages.references, 0u);
}

TEST(GpuUniformGridBuild, StagesAndPeakMemoryAreReported) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = test::make_triangle_soup(50000, 5, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.3f);
    cuda::DeviceBuildStages stages;
    const UniformGrid grid = cuda::build_uniform_grid_on_device(soup.triangles, 0, true, &stages);
    for (double ms : {stages.upload_ms, stages.bounds_ms, stages.cell_pairs_ms, stages.sort_ms, stages.cell_ranges_ms,
                      stages.proximity_ms, stages.download_ms}) {
        EXPECT_GT(ms, 0.0);
    }
    EXPECT_DOUBLE_EQ(stages.device_total_ms(), stages.bounds_ms + stages.sort_ms + stages.cell_pairs_ms +
                                                   stages.cell_ranges_ms + stages.proximity_ms);
    EXPECT_EQ(stages.references, grid.cell_prims.size());
    // At least the two double-buffered pair arrays were live at once.
    EXPECT_GE(stages.peak_device_bytes, 4 * grid.cell_prims.size() * sizeof(uint32_t));
}

TEST(GpuUniformGridBuild, HostMemoryBudgetIsRespected) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = test::make_triangle_soup(20000, 6, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f);
    const size_t previous = set_memory_budget(4096);
    EXPECT_THROW(cuda::build_uniform_grid_on_device(soup.triangles, 64, true), Error);
    set_memory_budget(previous);
}

TEST(GpuUniformGridBuild, ReferencesBeyond32BitsFailCleanly) {
    RF_REQUIRE_DEVICE();
    // Two triangles covering a 256 x 256 plane of cells, 70000 times: about
    // 4.6e9 (cell, triangle) pairs, more than 32-bit offsets hold (the count
    // and the scan run; nothing of that size is allocated).
    SceneGeometry square;
    for (int i = 0; i < 70000; ++i) {
        test::append(square, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(1, 1, 0)});
        test::append(square, {Vec3f(0, 0, 0), Vec3f(1, 1, 0), Vec3f(0, 1, 0)});
    }
    try {
        (void)cuda::build_uniform_grid_on_device(square.triangles, 256, false);
        ADD_FAILURE() << "expected rf::Error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("exceed 32-bit offsets"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace rf
