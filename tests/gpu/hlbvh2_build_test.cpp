// The CUDA HLBVH2 (Garanzha 2014 ch. 5; backend/cuda/hlbvh2_build.cu: the
// bottom trees in one launch) against the CPU HLBVH2: the same BVH (nodes and
// primitive order) on soups, spheres and degenerate inputs; the device's
// forest (order, clusters, references) equal to the CPU's sort and shared
// steps; the device's one-launch cluster boxes equal to the unions of their
// triangles' boxes;
// the device's top level (hlbvh2_top_level.cu, task queues) equal to the
// CPU's (build_hlbvh2_top_level over the same clusters) with its boxes (one
// launch with arrival counters) the level-wise unions of their children,
// bit for bit; the stage report filled. Skips with a message
// when no CUDA device is present.
#include <gtest/gtest.h>

#include <cstring>
#include <string>
#include <unordered_map>
#include <vector>

#include "../accel_test_scenes.h"
#include "gpu_build_checks.h"
#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/hlbvh2_emit.h"
#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "accel/bvh/builders/hlbvh2_top_steps.h"
#include "accel/bvh/builders/morton_tree.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/hlbvh2_build.h"
#include "backend/cuda/device_builders.h"

namespace rf {
namespace {

using gpu_build_test::append_degenerate_scenes;
using gpu_build_test::expect_same_bvh;
using gpu_build_test::NamedScene;
using gpu_build_test::same_box;

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes = gpu_build_test::common_scenes();
    scenes.push_back({"big soup", test::make_triangle_soup(300000, 2, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.05f)});
    append_degenerate_scenes(scenes);
    return scenes;
}

TEST(GpuHlbvh2Build, SameBvhAsCpuHlbvh2) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        for (int leaf_size : {1, 4, 8}) {
            const BvhBuildConfig config{.max_leaf_size = leaf_size};
            expect_same_bvh(build_hlbvh2(scene.geometry.triangles, config),
                            cuda::build_hlbvh2_on_device(scene.geometry.triangles, config),
                            scene.name + ", leaves of " + std::to_string(leaf_size));
        }
    }
}

TEST(GpuHlbvh2Build, EmptyAndSingleTriangle) {
    RF_REQUIRE_DEVICE();
    EXPECT_TRUE(cuda::build_hlbvh2_on_device({}, {}).nodes.empty());
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    const Bvh bvh = cuda::build_hlbvh2_on_device(one.triangles, {});
    ASSERT_EQ(bvh.nodes.size(), 1u);
    EXPECT_EQ(bvh.prim_indices, std::vector<uint32_t>{0});
}

TEST(GpuHlbvh2Build, DeviceForestAndClusterBoxes) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        SCOPED_TRACE(scene.name);
        morton::RawTree cpu(scene.geometry.triangles, BvhBuildConfig{});
        morton::Buffer<uint32_t> keys;
        cpu.sort_by_morton_codes(keys);
        const uint32_t n = cpu.size();
        const cuda::DeviceHlbvh2Forest dev = cuda::build_hlbvh2_forest_on_device(scene.geometry.triangles, 4);
        ASSERT_EQ(dev.forest.order, cpu.order);
        std::vector<uint32_t> begin;
        for (uint32_t i = 0; i < n; ++i) {
            if (i == 0 || (keys[i] >> 15) != (keys[i - 1] >> 15)) begin.push_back(i);
        }
        begin.push_back(n);
        ASSERT_EQ(dev.forest.cluster_begin, begin);
        size_t wrong = 0;
        for (size_t c = 0; c + 1 < begin.size(); ++c) {
            EXPECT_EQ(dev.forest.cluster_prefix[c], keys[begin[c]] >> 15);
            Box3f box = cpu.boxes[begin[c]];
            for (uint32_t i = begin[c]; i < begin[c + 1]; ++i) box = morton::box_union(box, cpu.boxes[i]);
            wrong += !same_box(box, dev.cluster_boxes[c]);
        }
        EXPECT_EQ(wrong, 0u) << "cluster boxes that differ";
    }
}

TEST(GpuHlbvh2Build, DeviceTopLevelIsTheCpuTopLevel) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        SCOPED_TRACE(scene.name);
        const cuda::DeviceHlbvh2Forest dev = cuda::build_hlbvh2_forest_on_device(scene.geometry.triangles, 4);
        const size_t clusters = dev.forest.cluster_prefix.size();
        if (clusters < 2) {
            EXPECT_TRUE(dev.forest.top_refs.empty());
            continue;
        }
        const uint32_t n = static_cast<uint32_t>(dev.forest.order.size());
        std::vector<hlbvh2::TopCluster> cpu(clusters);
        for (size_t c = 0; c < clusters; ++c) {
            cpu[c] = {dev.cluster_boxes[c], hlbvh2::pack_cells(dev.forest.cluster_prefix[c]),
                      dev.forest.cluster_begin[c + 1] - dev.forest.cluster_begin[c], dev.forest.refs[2 * (n - 1) + c]};
        }
        const std::vector<hlbvh2::TopCluster> original = cpu;
        ASSERT_EQ(dev.forest.top_refs, build_hlbvh2_top_level(cpu, n - 1));
        EXPECT_GE(dev.top_level_sizes.size(), 1u);
        // Each top box is the union of the clusters below it.
        ASSERT_EQ(dev.top_boxes.size(), clusters - 1);
        std::vector<Box3f> expected(clusters - 1);
        std::unordered_map<uint32_t, Box3f> cluster_box;
        for (const hlbvh2::TopCluster& c : original) cluster_box[c.root] = c.box;
        auto box_of = [&](uint32_t ref) {
            if ((ref & hlbvh2::kLeafRef) == 0 && ref >= n - 1) return expected[ref - (n - 1)];
            const auto it = cluster_box.find(ref);
            if (it == cluster_box.end()) {
                ADD_FAILURE() << "unknown reference " << ref;
                return Box3f{};
            }
            return it->second;
        };
        for (size_t k = clusters - 1; k-- > 0;) {  // children are numbered above their parent
            expected[k] = hlbvh2::box_union(box_of(dev.forest.top_refs[2 * k]), box_of(dev.forest.top_refs[2 * k + 1]));
        }
        size_t wrong = 0;
        for (size_t k = 0; k + 1 < clusters; ++k) wrong += !same_box(expected[k], dev.top_boxes[k]);
        EXPECT_EQ(wrong, 0u) << "top boxes that differ";
    }
}

TEST(GpuHlbvh2Build, StagesAreReported) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry g = test::make_triangle_soup(200000, 5, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.05f);
    cuda::DeviceBuildStages stages;
    (void)cuda::build_hlbvh2_on_device(g.triangles, {}, &stages);
    EXPECT_GT(stages.sort_ms, 0.0);
    EXPECT_GT(stages.clusters_ms, 0.0);
    EXPECT_GT(stages.bottom_ms, 0.0);
    EXPECT_GT(stages.boxes_ms, 0.0);
    EXPECT_GT(stages.top_ms, 0.0);
    EXPECT_GT(stages.device_emit_ms, 0.0);
    EXPECT_TRUE(stages.emitted_on_device);
    EXPECT_EQ(stages.emit_ms, 0.0);
    EXPECT_GT(stages.cluster_count, 1u);
    EXPECT_EQ(stages.bottom_levels, 1u);  // every bottom tree in one launch
    EXPECT_GT(stages.top_levels, 1u);
    EXPECT_GT(stages.peak_device_bytes, 200000u * sizeof(Triangle));
}

}  // namespace
}  // namespace rf
