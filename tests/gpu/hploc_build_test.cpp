// The CUDA H-PLOC (Benthin et al. 2024; backend/cuda/hploc_build.cu) against
// the CPU H-PLOC: the same BVH (nodes and primitive order) on soups, spheres
// and degenerate inputs for several radii and leaf sizes, a tree deeper than
// kBvhMaxDepth (emitted on the host), a large scene with thousands of warps
// racing for the boundary slots; the device's clustering checked directly
// (the CPU's Morton order, node boxes the unions of their children's, each
// node after its children); hits equal brute force; the stage report is
// filled. Skips with a message when no CUDA device is present.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "../accel_test_scenes.h"
#include "gpu_build_checks.h"
#include "accel/bvh/builders/hploc.h"
#include "accel/bvh/builders/morton_tree.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/hploc_build.h"

namespace rf {
namespace {

using gpu_build_test::append_degenerate_scenes;
using gpu_build_test::expect_same_bvh;
using gpu_build_test::NamedScene;
using gpu_build_test::same_box;

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes = gpu_build_test::common_scenes();
    scenes.push_back({"far", test::make_triangle_soup(3000, 3, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    SceneGeometry nested;  // one centre, growing triangles: equal codes, different boxes
    for (int i = 1; i <= 500; ++i) {
        const float s = 0.01f * static_cast<float>(i);
        test::append(nested, {Vec3f(-s, -s, 0), Vec3f(s, -s, 0), Vec3f(0, s, 0)});
    }
    scenes.push_back({"equal codes", std::move(nested)});
    scenes.push_back({"morton chain", test::make_morton_chain(2000)});  // deeper than kBvhMaxDepth
    for (int count : {3, 17, 33}) {
        scenes.push_back({std::to_string(count) + " triangles",
                          test::make_triangle_soup(static_cast<size_t>(count), 9, {Vec3f(0.0f), Vec3f(1.0f)}, 0.1f)});
    }
    append_degenerate_scenes(scenes);
    return scenes;
}

TEST(GpuHplocBuild, SameBvhAsCpuHploc) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        for (int radius : {1, 8, 16, 31}) {
            for (int leaf_size : {1, 4}) {
                const BvhBuildConfig config{.max_leaf_size = leaf_size};
                const PlocOptions options{.radius = radius};
                const std::string what = scene.name + ", radius " + std::to_string(radius) + ", leaves of " +
                                         std::to_string(leaf_size);
                expect_same_bvh(build_hploc(scene.geometry.triangles, config, options),
                                cuda::build_hploc_on_device(scene.geometry.triangles, config, options), what);
            }
        }
    }
}

TEST(GpuHplocBuild, SameBvhThroughTheDispatch) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = test::make_triangle_soup(50000, 6, {Vec3f(-30.0f), Vec3f(30.0f)}, 0.5f);
    BuildOptions options{.builder = Builder::Hploc};
    const Bvh cpu = build_bvh(soup.triangles, options);
    options.device = Device{Device::Kind::Cuda, 0};
    BuildReport report;
    expect_same_bvh(cpu, build_bvh(soup.triangles, options, &report), "dispatch");
    EXPECT_TRUE(report.on_device);
}

TEST(GpuHplocBuild, EmptyAndSingleTriangle) {
    RF_REQUIRE_DEVICE();
    EXPECT_TRUE(cuda::build_hploc_on_device({}, {}, {}).nodes.empty());
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    const Bvh bvh = cuda::build_hploc_on_device(one.triangles, {}, {});
    ASSERT_EQ(bvh.nodes.size(), 1u);
    EXPECT_EQ(bvh.prim_indices, std::vector<uint32_t>{0});
    EXPECT_TRUE(same_box(bvh.nodes[0].bounds, build_hploc(one.triangles, {}, {}).nodes[0].bounds));
}

// The device's own clustering: the CPU's Morton order, each node after its
// children with its box the union of theirs, and the CPU's BVH from it.
void check_clustering(const SceneGeometry& g, int radius, const std::string& what) {
    SCOPED_TRACE(what + ", radius " + std::to_string(radius));
    morton::RawTree cpu(g.triangles, BvhBuildConfig{});
    morton::Buffer<uint64_t> keys;
    cpu.sort_by_morton_codes(keys);
    const uint32_t n = cpu.size();
    cuda::DeviceBuildStages stages;
    cuda::DeviceHplocTree dev = cuda::build_hploc_tree_on_device(g.triangles, radius, &stages);
    ASSERT_EQ(dev.order, cpu.order);
    ASSERT_EQ(dev.children.size(), 2 * size_t{n - 1});
    ASSERT_EQ(dev.node_boxes.size(), size_t{n - 1});
    EXPECT_GT(stages.hploc_ms, 0.0);
    size_t wrong_boxes = 0;
    for (uint32_t k = 0; k + 1 < n; ++k) {
        Box3f box[2];
        for (int c = 0; c < 2; ++c) {
            const uint32_t ref = dev.children[2 * size_t{k} + c];
            ASSERT_TRUE(morton::is_leaf_ref(ref) || ref < k) << "node " << k << " made before its child " << ref;
            box[c] = morton::is_leaf_ref(ref) ? cpu.boxes[ref & ~morton::kLeafRef] : dev.node_boxes[ref];
        }
        wrong_boxes += !same_box(dev.node_boxes[k], morton::box_union(box[0], box[1]));
    }
    EXPECT_EQ(wrong_boxes, 0u);
    expect_same_bvh(build_hploc(g.triangles, BvhBuildConfig{}, PlocOptions{.radius = radius}),
                    emit_hploc_tree(g.triangles, BvhBuildConfig{}, std::move(dev.order), dev.children), what);
}

TEST(GpuHplocBuild, DeviceClusteringAndNodeBoxes) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        if (scene.geometry.triangles.size() < 2) continue;
        check_clustering(scene.geometry, 16, scene.name);
    }
    // Thousands of warps; repeated, since the schedule differs from run to run.
    const SceneGeometry big = test::make_triangle_soup(1000000, 9, {Vec3f(-100.0f), Vec3f(100.0f)}, 0.5f);
    for (int run = 0; run < 3; ++run) check_clustering(big, 8, "1M soup, run " + std::to_string(run));
}

TEST(GpuHplocBuild, StagesAndPeakMemoryAreReported) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = test::make_triangle_soup(200000, 4, {Vec3f(-50.0f), Vec3f(50.0f)}, 0.5f);
    cuda::DeviceBuildStages stages;
    const Bvh bvh = cuda::build_hploc_on_device(soup.triangles, {}, {}, &stages);
    EXPECT_FALSE(bvh.nodes.empty());
    for (double ms : {stages.upload_ms, stages.bounds_ms, stages.morton_ms, stages.sort_ms, stages.hploc_ms,
                      stages.device_emit_ms, stages.download_ms}) {
        EXPECT_GT(ms, 0.0);
    }
    EXPECT_TRUE(stages.emitted_on_device);
    EXPECT_EQ(stages.emit_ms, 0.0);
    EXPECT_DOUBLE_EQ(stages.device_total_ms(),
                     stages.bounds_ms + stages.morton_ms + stages.sort_ms + stages.hploc_ms + stages.device_emit_ms);
    EXPECT_GE(stages.peak_device_bytes, soup.triangles.size() * sizeof(Triangle));
}

TEST(GpuHplocBuild, HitsEqualBruteForce) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = gpu_build_test::hit_test_soup();
    gpu_build_test::expect_hits_equal_brute_force(soup, cuda::build_hploc_on_device(soup.triangles, {}, {}), "hploc");
}

}  // namespace
}  // namespace rf
