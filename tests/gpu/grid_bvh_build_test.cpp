// The CUDA GridBvh / GridBvhSplit (Garanzha 2014 ch. 4; backend/cuda/
// grid_bvh_build.cu: partial triangles, one key sort, the sparse grid by
// compaction, EmitHierarchy by task queues) against rf::build_grid_bvh: the
// same BVH (nodes bit for bit and primitive order) for both variants on
// soups, a sphere, long slivers and the degenerate inputs; GridBvhSplit's
// references the CPU's count and within the budget exactly; the leaf
// finishing and canonical emission on the device (grid_bvh_finish_steps.h)
// on every scene whose leaves fit one thread, the host's when a crowded cell
// does not; the stage report filled. Skips with a message when no CUDA
// device is present.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "../accel_test_scenes.h"
#include "accel/bvh/builders/grid_bvh.h"
#include "backend/cuda/device_bvh_builders.h"
#include "gpu_build_checks.h"
#include "backend/cuda/device_builders.h"

namespace rf {
namespace {

using gpu_build_test::append_degenerate_scenes;
using gpu_build_test::expect_same_bvh;
using gpu_build_test::NamedScene;

// Long thin triangles along the diagonals among small ones: what GridBvhSplit splits.
SceneGeometry make_slivers(int count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-10.0f, 10.0f);
    SceneGeometry g;
    for (int i = 0; i < count; ++i) {
        const Vec3f a(u(rng), u(rng), u(rng));
        const Vec3f d(1.0f, (i & 1) ? 1.0f : -1.0f, (i & 2) ? 1.0f : -1.0f);
        const float length = (i % 4 == 0) ? 6.0f : 0.2f;
        test::append(g, {a, a + d * length, a + test::random_direction(rng) * 0.05f});
    }
    return g;
}

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes = gpu_build_test::common_scenes();
    scenes.push_back({"big soup", test::make_triangle_soup(200000, 2, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.05f)});
    scenes.push_back({"slivers", make_slivers(20000, 3)});
    append_degenerate_scenes(scenes);
    return scenes;
}

TEST(GpuGridBvhBuild, SameBvhAsCpuForBothVariants) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        for (const bool split : {false, true}) {
            for (const int leaf_size : {1, 4}) {
                const BvhBuildConfig config{.max_leaf_size = leaf_size};
                const GridBvhOptions grid_bvh{.split_budget = 0.5f};
                const std::string what = scene.name + (split ? ", split" : "") + ", leaves of " + std::to_string(leaf_size);
                cuda::DeviceBuildStages stages;
                expect_same_bvh(
                    build_grid_bvh(scene.geometry.triangles, config, grid_bvh, split),
                    cuda::build_grid_bvh_on_device(scene.geometry.triangles, config, grid_bvh, split, &stages), what);
                // Only "one point" (1000 references in one Grid0 cell) has a leaf over the device's cap.
                EXPECT_EQ(stages.emitted_on_device, scene.name != "one point") << what;
            }
        }
    }
}

TEST(GpuGridBvhBuild, SplitReferencesAreTheCpusWithinTheBudget) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry slivers = make_slivers(20000, 4);
    const size_t n = slivers.triangles.size();
    for (const float budget : {0.05f, 0.3f, 2.0f, 10.0f}) {
        const GridBvhOptions grid_bvh{.split_budget = budget};
        GridBvhStages cpu;
        const Bvh expected = build_grid_bvh(slivers.triangles, BvhBuildConfig{}, grid_bvh, true, &cpu);
        cuda::DeviceBuildStages dev;
        const Bvh got = cuda::build_grid_bvh_on_device(slivers.triangles, BvhBuildConfig{}, grid_bvh, true, &dev);
        EXPECT_EQ(cpu.references, dev.references) << budget;
        EXPECT_LE(dev.references - n, size_t(std::floor(double(budget) * double(n)))) << budget;
        expect_same_bvh(expected, got, "slivers, budget " + std::to_string(budget));
    }
}

TEST(GpuGridBvhBuild, EmptySingleAndOnePoint) {
    RF_REQUIRE_DEVICE();
    EXPECT_TRUE(cuda::build_grid_bvh_on_device({}, {}, {}, false).nodes.empty());
    EXPECT_TRUE(cuda::build_grid_bvh_on_device({}, {}, {}, true).nodes.empty());
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    for (const bool split : {false, true}) {
        const Bvh bvh = cuda::build_grid_bvh_on_device(one.triangles, {}, {}, split);
        ASSERT_EQ(bvh.nodes.size(), 1u);
        EXPECT_EQ(bvh.prim_indices, std::vector<uint32_t>{0});
    }
}

TEST(GpuGridBvhBuild, StagesAreReported) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = make_slivers(50000, 5);
    GridBvhStages cpu;
    build_grid_bvh(soup.triangles, BvhBuildConfig{}, GridBvhOptions{}, true, &cpu);
    cuda::DeviceBuildStages s;
    cuda::build_grid_bvh_on_device(soup.triangles, BvhBuildConfig{}, GridBvhOptions{}, true, &s);
    EXPECT_GT(s.partial_triangles_ms, 0.0);
    EXPECT_GT(s.sort_ms, 0.0);
    EXPECT_GT(s.grid0_ms, 0.0);
    EXPECT_GT(s.coarse_levels_ms, 0.0);
    EXPECT_GT(s.hierarchy_ms, 0.0);
    EXPECT_GT(s.download_ms, 0.0);
    EXPECT_GT(s.leaf_finish_ms, 0.0);
    EXPECT_TRUE(s.emitted_on_device);
    EXPECT_GT(s.device_emit_ms, 0.0);
    EXPECT_EQ(s.emit_ms, 0.0);  // no host emission
    EXPECT_GT(s.device_total_ms(), 0.0);
    EXPECT_EQ(s.references, cpu.references);
    EXPECT_EQ(s.occupied_top_cells, cpu.occupied_top_cells);
    EXPECT_GT(s.peak_device_bytes, s.references * 32);
}

TEST(GpuGridBvhBuild, CrowdedCellFallsBackToTheHostEmission) {
    RF_REQUIRE_DEVICE();
    // 200 identical triangles: one Grid0 cell, one leaf over kDeviceFinishRefs.
    SceneGeometry same;
    for (int i = 0; i < 200; ++i) test::append(same, {Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1)});
    for (const bool split : {false, true}) {
        cuda::DeviceBuildStages s;
        const Bvh got = cuda::build_grid_bvh_on_device(same.triangles, BvhBuildConfig{}, GridBvhOptions{}, split, &s);
        expect_same_bvh(build_grid_bvh(same.triangles, BvhBuildConfig{}, GridBvhOptions{}, split), got,
                        std::string("200 identical triangles") + (split ? ", split" : ""));
        EXPECT_FALSE(s.emitted_on_device);
        EXPECT_EQ(s.device_emit_ms, 0.0);
        EXPECT_GT(s.emit_ms, 0.0);
        EXPECT_GT(s.download_ms, 0.0);
    }
}

}  // namespace
}  // namespace rf
