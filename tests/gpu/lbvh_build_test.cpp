// The CUDA LBVH (Karras 2012; backend/cuda/lbvh_build.cu) against the CPU
// LBVH: the same BVH (nodes and primitive order) on soups, spheres and
// degenerate inputs with 30- and 63-bit codes; the device's raw radix tree,
// parents, arrival counters and bottom-up boxes checked directly; hits of the
// downloaded BVH (host traversal) equal brute force; the stage report is
// filled. Skips with a message when no CUDA device is present.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "../accel_test_scenes.h"
#include "gpu_build_checks.h"
#include "accel/brute_force.h"
#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/lbvh.h"
#include "accel/bvh/builders/morton_tree.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/lbvh_build.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using gpu_build_test::append_degenerate_scenes;
using gpu_build_test::expect_same_bvh;
using gpu_build_test::NamedScene;
using gpu_build_test::same_box;

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes = gpu_build_test::common_scenes();
    scenes.push_back({"far", test::make_triangle_soup(3000, 3, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    append_degenerate_scenes(scenes);
    return scenes;
}

TEST(GpuLbvhBuild, SameBvhAsCpuLbvh) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        for (int bits : {30, 63}) {
            for (int leaf_size : {1, 4}) {
                const BvhBuildConfig config{.max_leaf_size = leaf_size};
                const std::string what = scene.name + ", " + std::to_string(bits) + " bits, leaves of " +
                                         std::to_string(leaf_size);
                expect_same_bvh(build_lbvh(scene.geometry.triangles, config, bits),
                                cuda::build_lbvh_on_device(scene.geometry.triangles, config, bits), what);
            }
        }
    }
}

TEST(GpuLbvhBuild, EmptyAndSingleTriangle) {
    RF_REQUIRE_DEVICE();
    for (int bits : {30, 63}) {
        EXPECT_TRUE(cuda::build_lbvh_on_device({}, {}, bits).nodes.empty());
        SceneGeometry one;
        test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
        const Bvh bvh = cuda::build_lbvh_on_device(one.triangles, {}, bits);
        ASSERT_EQ(bvh.nodes.size(), 1u);
        EXPECT_EQ(bvh.nodes[0].count, 1u);
        EXPECT_EQ(bvh.prim_indices, std::vector<uint32_t>{0});
        EXPECT_TRUE(same_box(bvh.nodes[0].bounds, build_lbvh(one.triangles, {}, bits).nodes[0].bounds));
    }
    EXPECT_THROW((void)cuda::build_lbvh_on_device({}, {}, 32), Error);
}

// The device's own radix tree: the order and inner nodes of the CPU's
// Morton sort and Karras construction, consistent parents, every counter
// reached twice, every inner box the union of its children's.
template <class Key>
void check_raw_tree(const SceneGeometry& g, const std::string& what) {
    const int bits = sizeof(Key) == 4 ? 30 : 63;
    SCOPED_TRACE(what + ", " + std::to_string(bits) + " bits");
    morton::RawTree cpu(g.triangles, BvhBuildConfig{});
    morton::Buffer<Key> keys;
    cpu.sort_by_morton_codes(keys);
    const uint32_t n = cpu.size();
    const cuda::DeviceKarrasTree dev = cuda::build_karras_tree_on_device(g.triangles, bits);
    ASSERT_EQ(dev.order, cpu.order);
    std::vector<uint32_t> children(2 * size_t{n - 1});
    for (uint32_t i = 0; i + 1 < n; ++i) karras::build_inner(keys.data(), n, i, &children[2 * size_t{i}], nullptr, nullptr);
    ASSERT_EQ(dev.children, children);
    for (uint32_t i = 0; i < n; ++i) ASSERT_TRUE(same_box(dev.triangle_boxes[cpu.order[i]], cpu.boxes[i])) << i;
    EXPECT_EQ(dev.inner_parent[0], karras::kNoParent);
    size_t wrong_parents = 0, wrong_boxes = 0, wrong_counts = 0;
    for (uint32_t i = 0; i + 1 < n; ++i) {
        Box3f box[2];
        for (int c = 0; c < 2; ++c) {
            const uint32_t ref = dev.children[2 * size_t{i} + c];
            const bool leaf = karras::is_leaf_ref(ref);
            const uint32_t index = ref & ~karras::kLeafRef;
            wrong_parents += (leaf ? dev.leaf_parent[index] : dev.inner_parent[index]) != i;
            box[c] = leaf ? cpu.boxes[index] : dev.inner_boxes[index];
        }
        wrong_boxes += !same_box(dev.inner_boxes[i], morton::box_union(box[0], box[1]));
        wrong_counts += dev.arrivals[i] != 2;
    }
    EXPECT_EQ(wrong_parents, 0u);
    EXPECT_EQ(wrong_boxes, 0u);
    EXPECT_EQ(wrong_counts, 0u);
}

TEST(GpuLbvhBuild, DeviceRadixTreeParentsAndBoxes) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : test_scenes()) {
        check_raw_tree<uint32_t>(scene.geometry, scene.name);
        check_raw_tree<uint64_t>(scene.geometry, scene.name);
    }
    // Large enough for many blocks to race on the counters.
    const SceneGeometry big = test::make_triangle_soup(300000, 9, {Vec3f(-100.0f), Vec3f(100.0f)}, 0.5f);
    check_raw_tree<uint32_t>(big, "300K soup");
}

TEST(GpuLbvhBuild, StagesAndPeakMemoryAreReported) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = test::make_triangle_soup(200000, 4, {Vec3f(-50.0f), Vec3f(50.0f)}, 0.5f);
    for (int bits : {30, 63}) {
        cuda::DeviceBuildStages stages;
        const Bvh bvh = cuda::build_lbvh_on_device(soup.triangles, {}, bits, &stages);
        EXPECT_FALSE(bvh.nodes.empty());
        for (double ms : {stages.upload_ms, stages.bounds_ms, stages.morton_ms, stages.sort_ms, stages.inner_nodes_ms,
                          stages.device_emit_ms, stages.download_ms}) {
            EXPECT_GT(ms, 0.0);
        }
        // The device emitted the BVH (it computes the boxes itself, so the box pass is skipped).
        EXPECT_TRUE(stages.emitted_on_device);
        EXPECT_EQ(stages.emit_ms, 0.0);
        EXPECT_EQ(stages.boxes_ms, 0.0);
        EXPECT_DOUBLE_EQ(stages.device_total_ms(), stages.bounds_ms + stages.morton_ms + stages.sort_ms +
                                                       stages.inner_nodes_ms + stages.device_emit_ms);
        // At least the triangles, or the boxes plus the tree, were on the device at once.
        EXPECT_GE(stages.peak_device_bytes, soup.triangles.size() * sizeof(Triangle));
    }
}

// The device leaves trees deeper than kBvhMaxDepth to the host's
// depth-limited emitter; the BVH is still the CPU's.
TEST(GpuLbvhBuild, TreesDeeperThanTheLimitAreEmittedByTheHost) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry chain = test::make_morton_chain(2000);
    for (int leaf_size : {1, 4}) {
        const BvhBuildConfig config{.max_leaf_size = leaf_size};
        cuda::DeviceBuildStages stages;
        expect_same_bvh(build_lbvh(chain.triangles, config, 63),
                        cuda::build_lbvh_on_device(chain.triangles, config, 63, &stages),
                        "Morton chain, leaves of " + std::to_string(leaf_size));
        EXPECT_FALSE(stages.emitted_on_device);
        EXPECT_GT(stages.emit_ms, 0.0);
        EXPECT_GT(stages.device_emit_ms, 0.0);  // the bottom-up pass ran before the depth check
    }
}

TEST(GpuLbvhBuild, HitsEqualBruteForce) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = gpu_build_test::hit_test_soup();
    for (int bits : {30, 63})
        gpu_build_test::expect_hits_equal_brute_force(soup, cuda::build_lbvh_on_device(soup.triangles, {}, bits),
                                                      std::to_string(bits) + " bits");
}

}  // namespace
}  // namespace rf
