// The CUDA PLOC (Meister and Bittner 2018; backend/cuda/ploc_build.cu)
// against the CPU PLOC: the same BVH (nodes and primitive order) on soups,
// spheres and degenerate inputs, with the shared-memory window search
// (radius 1, 16) and the plain one (radius 300), scenes small enough for
// the single-block tail alone and large enough for grid iterations first; the device's clustering
// checked directly (the CPU's Morton order, node boxes the unions of their
// children, every node made once); hits equal brute force; the stage report
// is filled. Skips with a message when no CUDA device is present.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "../accel_test_scenes.h"
#include "gpu_build_checks.h"
#include "accel/brute_force.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel/bvh/builders/ploc.h"
#include "accel/bvh/builders/ploc_emit.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/ploc_build.h"
#include "backend/cuda/device_builders.h"

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
    // More clusters than the single-block tail holds (3,072): grid iterations
    // first, also with the plain search (radius 300, scenes up to 5,000).
    scenes.push_back({"grid phase", test::make_triangle_soup(4500, 6, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    SceneGeometry crowd;  // equal boxes through the grid phase and the tail
    for (int i = 0; i < 4000; ++i) test::append(crowd, {Vec3f(2.0f), Vec3f(2.0f), Vec3f(2.0f)});
    scenes.push_back({"one point, grid phase", std::move(crowd)});
    append_degenerate_scenes(scenes);
    return scenes;
}

TEST(GpuPlocBuild, SameBvhAsCpuPloc) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        for (int radius : {1, 16, 300}) {
            // The plain search of radius 300 is slow on the CPU side: smaller scenes only.
            if (radius == 300 && scene.geometry.triangles.size() > 5000) continue;
            for (int leaf_size : {1, 4}) {
                const BvhBuildConfig config{.max_leaf_size = leaf_size};
                const PlocOptions ploc{.radius = radius};
                const std::string what = scene.name + ", radius " + std::to_string(radius) + ", leaves of " +
                                         std::to_string(leaf_size);
                expect_same_bvh(build_ploc(scene.geometry.triangles, config, ploc),
                                cuda::build_ploc_on_device(scene.geometry.triangles, config, ploc), what);
            }
        }
    }
}

TEST(GpuPlocBuild, EmptyAndSingleTriangle) {
    RF_REQUIRE_DEVICE();
    EXPECT_TRUE(cuda::build_ploc_on_device({}, {}, {}).nodes.empty());
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    const Bvh bvh = cuda::build_ploc_on_device(one.triangles, {}, {});
    ASSERT_EQ(bvh.nodes.size(), 1u);
    EXPECT_EQ(bvh.nodes[0].count, 1u);
    EXPECT_EQ(bvh.prim_indices, std::vector<uint32_t>{0});
    EXPECT_TRUE(same_box(bvh.nodes[0].bounds, build_ploc(one.triangles, {}, {}).nodes[0].bounds));
}

// The device's own clustering: the CPU's Morton order, every node's box the
// union of its children's, and the CPU's BVH from it.
void check_clustering(const SceneGeometry& g, int radius, const std::string& what) {
    SCOPED_TRACE(what + ", radius " + std::to_string(radius));
    morton::RawTree cpu(g.triangles, BvhBuildConfig{});
    morton::Buffer<uint64_t> keys;
    cpu.sort_by_morton_codes(keys);
    const uint32_t n = cpu.size();
    cuda::DeviceBuildStages stages;
    cuda::DevicePlocTree dev = cuda::build_ploc_tree_on_device(g.triangles, radius, &stages);
    ASSERT_EQ(dev.order, cpu.order);
    ASSERT_EQ(dev.children.size(), 2 * size_t{n - 1});
    ASSERT_EQ(dev.node_boxes.size(), size_t{n - 1});
    EXPECT_EQ(stages.ploc_iterations, dev.iteration_nodes.size());
    size_t wrong_boxes = 0;
    for (uint32_t k = 0; k + 1 < n; ++k) {
        Box3f box[2];
        for (int c = 0; c < 2; ++c) {
            const uint32_t ref = dev.children[2 * size_t{k} + c];
            box[c] = morton::is_leaf_ref(ref) ? cpu.boxes[ref & ~morton::kLeafRef] : dev.node_boxes[ref];
        }
        wrong_boxes += !same_box(dev.node_boxes[k], morton::box_union(box[0], box[1]));
    }
    EXPECT_EQ(wrong_boxes, 0u);
    expect_same_bvh(build_ploc(g.triangles, BvhBuildConfig{}, PlocOptions{.radius = radius}),
                    emit_ploc_tree(g.triangles, BvhBuildConfig{}, std::move(dev.order), dev.children,
                                   dev.iteration_nodes),
                    what);
}

TEST(GpuPlocBuild, DeviceClusteringAndNodeBoxes) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        if (scene.geometry.triangles.size() < 2) continue;
        check_clustering(scene.geometry, 16, scene.name);
    }
    // Many blocks, many iterations.
    const SceneGeometry big = test::make_triangle_soup(300000, 9, {Vec3f(-100.0f), Vec3f(100.0f)}, 0.5f);
    check_clustering(big, 16, "300K soup");
    check_clustering(big, 1, "300K soup");
}

TEST(GpuPlocBuild, StagesAndPeakMemoryAreReported) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = test::make_triangle_soup(200000, 4, {Vec3f(-50.0f), Vec3f(50.0f)}, 0.5f);
    cuda::DeviceBuildStages stages;
    const Bvh bvh = cuda::build_ploc_on_device(soup.triangles, {}, {}, &stages);
    EXPECT_FALSE(bvh.nodes.empty());
    for (double ms : {stages.upload_ms, stages.bounds_ms, stages.morton_ms, stages.sort_ms, stages.ploc_ms,
                      stages.device_emit_ms, stages.download_ms}) {
        EXPECT_GT(ms, 0.0);
    }
    EXPECT_TRUE(stages.emitted_on_device);
    EXPECT_EQ(stages.emit_ms, 0.0);
    EXPECT_GT(stages.ploc_iterations, 1u);
    EXPECT_DOUBLE_EQ(stages.device_total_ms(),
                     stages.bounds_ms + stages.morton_ms + stages.sort_ms + stages.ploc_ms + stages.device_emit_ms);
    EXPECT_GE(stages.peak_device_bytes, soup.triangles.size() * sizeof(Triangle));
}

TEST(GpuPlocBuild, HitsEqualBruteForce) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = gpu_build_test::hit_test_soup();
    gpu_build_test::expect_hits_equal_brute_force(soup, cuda::build_ploc_on_device(soup.triangles, {}, {}), "ploc");
}

}  // namespace
}  // namespace rf
