// Binned SAH builder: structural invariants of the canonical BVH over
// several scenes, thread counts, leaf sizes and bin counts; determinism; the
// SAH metric; empty, single and degenerate inputs.
#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/build_bvh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "accel_test_scenes.h"
#include "bvh_invariants.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using test::check_bvh;
using test::identical;
using test::same_box;
using test::TreeShape;

// Unit triangles at x = 1.09^i: with two bins every split halves the extent
// and peels off only the ~8 farthest triangles, which would make a chain over
// 100 levels deep without the depth limit.
SceneGeometry make_geometric_row(int count) {
    SceneGeometry g;
    float x = 1.0f;
    for (int i = 0; i < count; ++i, x *= 1.09f) {
        test::append(g, {Vec3f(x, 0, 0), Vec3f(x, 1, 0), Vec3f(x, 0, 1)});
    }
    return g;
}

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(3000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    scenes.push_back({"far", test::make_triangle_soup(2000, 3, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    scenes.push_back({"geometric", make_geometric_row(900)});
    SceneGeometry same;
    for (int i = 0; i < 100; ++i) test::append(same, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    scenes.push_back({"identical", std::move(same)});
    return scenes;
}

TEST(BvhBuild, InvariantsHoldForScenesLeafSizesBinsAndThreads) {
    for (const NamedScene& scene : test_scenes()) {
        for (int leaf_size : {1, 4, 16}) {
            for (int bins : {2, 16, 256}) {
                for (int threads : {1, 2}) {
                    SCOPED_TRACE(scene.name + " leaf " + std::to_string(leaf_size) + " bins " +
                                 std::to_string(bins) + " threads " + std::to_string(threads));
                    const BuildOptions options{
                        .threads = threads, .max_leaf_size = leaf_size, .binned = {.bin_count = bins}};
                    const Bvh bvh = build_bvh(scene.geometry.triangles, options);
                    check_bvh(bvh, scene.geometry.triangles, leaf_size);
                }
            }
        }
    }
}

TEST(BvhBuild, DepthStaysWithinLimitOnPathologicalInput) {
    const SceneGeometry row = make_geometric_row(900);
    for (int leaf_size : {1, 4}) {
        const Bvh bvh = build_binned_sah(row.triangles, BvhBuildConfig{.max_leaf_size = leaf_size},
                                         BinnedSahOptions{.bin_count = 2});
        const TreeShape shape = check_bvh(bvh, row.triangles, leaf_size);
        EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        EXPECT_GT(shape.max_depth, 50);  // the input really is lopsided
    }
}

TEST(BvhBuild, SameTreeForEveryThreadCount) {
    // Large enough for parallel binning (> 64K primitives per node) and subtree tasks.
    const SceneGeometry soup = test::make_triangle_soup(150000, 5, {Vec3f(-100.0f), Vec3f(100.0f)}, 1.0f);
    const Bvh one = build_bvh(soup.triangles, BuildOptions{.builder = Builder::BinnedSah, .threads = 1});
    const Bvh two = build_bvh(soup.triangles, BuildOptions{.builder = Builder::BinnedSah, .threads = 2});
    const Bvh all = build_bvh(soup.triangles, BuildOptions{.builder = Builder::BinnedSah, .threads = 0});
    EXPECT_TRUE(identical(one, two));
    EXPECT_TRUE(identical(one, all));
    check_bvh(one, soup.triangles, 4);
}

TEST(BvhBuild, LeafSizeOneGivesOneTrianglePerLeaf) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(2));
    const Bvh bvh = build_binned_sah(sphere.triangles, BvhBuildConfig{.max_leaf_size = 1}, BinnedSahOptions{});
    EXPECT_EQ(bvh.leaf_count(), sphere.triangles.size());
    EXPECT_EQ(bvh.nodes.size(), 2 * sphere.triangles.size() - 1);
}

TEST(BvhBuild, SahCostOfHandBuiltTree) {
    Bvh bvh;
    bvh.nodes.resize(3);
    bvh.nodes[0].bounds = {Vec3f(0, 0, 0), Vec3f(2, 1, 1)};  // area 2 * (2 + 1 + 2) = 10
    bvh.nodes[0].first = 1;
    bvh.nodes[1].bounds = {Vec3f(0, 0, 0), Vec3f(1, 1, 1)};  // area 6
    bvh.nodes[1].count = 2;
    bvh.nodes[2].bounds = {Vec3f(1, 0, 0), Vec3f(2, 1, 0.5f)};  // area 2 * (1 + 0.5 + 0.5) = 4
    bvh.nodes[2].first = 2;
    bvh.nodes[2].count = 3;
    bvh.prim_indices = {0, 1, 2, 3, 4};
    EXPECT_DOUBLE_EQ(bvh.sah_cost(), 1.0 + 0.6 * 2 + 0.4 * 3);
    EXPECT_DOUBLE_EQ(bvh.sah_cost(2.0f, 0.5f), 2.0 + 0.5 * (0.6 * 2 + 0.4 * 3));
    EXPECT_EQ(bvh.leaf_count(), 2u);
    EXPECT_EQ(bvh.memory_bytes(), 3 * 32u + 5 * 4u);
}

TEST(BvhBuild, SahPrefersSplittingSeparatedClusters) {
    // Two far-apart clusters: the root must split them, and the SAH cost must
    // be far below that of one big leaf (1 * 8 triangles).
    SceneGeometry g;
    for (int i = 0; i < 4; ++i) {
        const float d = 0.1f * i;
        test::append(g, {Vec3f(d, 0, 0), Vec3f(d + 0.1f, 0, 0), Vec3f(d, 0.1f, 0)});
        test::append(g, {Vec3f(100 + d, 0, 0), Vec3f(100 + d + 0.1f, 0, 0), Vec3f(100 + d, 0.1f, 0)});
    }
    const Bvh bvh = build_binned_sah(g.triangles, BvhBuildConfig{.max_leaf_size = 8}, BinnedSahOptions{});
    check_bvh(bvh, g.triangles, 8);
    ASSERT_GT(bvh.nodes.size(), 1u);
    EXPECT_LT(bvh.nodes[1].bounds.hi.x, 1.0f);
    EXPECT_GT(bvh.nodes[2].bounds.lo.x, 99.0f);
    EXPECT_LT(bvh.sah_cost(), 2.0);
}

TEST(BvhBuild, EmptyAndSingleTriangle) {
    const Bvh empty = build_binned_sah({}, BvhBuildConfig{}, BinnedSahOptions{});
    EXPECT_TRUE(empty.nodes.empty());
    EXPECT_TRUE(empty.prim_indices.empty());
    EXPECT_EQ(empty.leaf_count(), 0u);
    EXPECT_EQ(empty.sah_cost(), 0.0);

    const Triangle tri{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)};
    const Bvh one = build_binned_sah(std::span<const Triangle>(&tri, 1), BvhBuildConfig{}, BinnedSahOptions{});
    ASSERT_EQ(one.nodes.size(), 1u);
    EXPECT_EQ(one.nodes[0].count, 1u);
    EXPECT_TRUE(same_box(one.nodes[0].bounds, tri.bounds()));
    EXPECT_DOUBLE_EQ(one.sah_cost(), 1.0);
}

TEST(BvhBuild, AllPointTrianglesAtOnePlace) {
    SceneGeometry g;
    for (int i = 0; i < 50; ++i) test::append(g, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    const Bvh bvh = build_binned_sah(g.triangles, BvhBuildConfig{.max_leaf_size = 4}, BinnedSahOptions{});
    check_bvh(bvh, g.triangles, 4);
    EXPECT_TRUE(std::isfinite(bvh.sah_cost()));
}

TEST(BvhBuild, AccelStatsDescribeTheTree) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(3));
    BuildOptions options;
    options.layout = Layout::Bvh2;
    const auto accel = build_accel(sphere, options);
    const AccelStats stats = accel->stats();
    EXPECT_EQ(stats.name, "bvh/binned/bvh2");
    EXPECT_EQ(build_accel(sphere)->stats().name, "bvh/binned/bvh8");  // the default combination
    EXPECT_GT(stats.node_count, 1u);
    EXPECT_EQ(stats.node_count, 2 * stats.leaf_count - 1);
    EXPECT_EQ(stats.bytes, stats.node_count * 32 + sphere.triangles.size() * 4);
    EXPECT_GT(stats.sah_cost, 1.0);
    EXPECT_GE(stats.build_ms, 0.0);
}

TEST(BvhBuild, InvalidOptionsAndNamesThrow) {
    const SceneGeometry g = test::to_geometry(test::make_icosphere(0));
    EXPECT_THROW((void)build_accel(g, BuildOptions{.binned = {.bin_count = 1}}), Error);
    EXPECT_THROW((void)build_accel(g, BuildOptions{.binned = {.bin_count = 257}}), Error);
    EXPECT_THROW((void)build_accel(g, BuildOptions{.max_leaf_size = 0}), Error);
    EXPECT_THROW((void)build_accel(g, BuildOptions{.max_leaf_size = 65}), Error);
    EXPECT_THROW((void)build_accel(g, BuildOptions{.sah = {.traversal = 0.0f}}), Error);
    EXPECT_THROW((void)build_accel(g, BuildOptions{.sah = {.intersection = -1.0f}}), Error);
    EXPECT_THROW((void)build_accel(g, BuildOptions{.sah = {.intersection = NAN}}), Error);
    EXPECT_THROW((void)build_accel(g, BuildOptions{.threads = -1}), Error);
    EXPECT_NO_THROW((void)build_accel(g, BuildOptions{.max_leaf_size = 64, .binned = {.bin_count = 2}}));
    EXPECT_EQ(parse_structure("bvh"), Structure::Bvh);
    EXPECT_EQ(parse_structure("brute"), Structure::BruteForce);
    EXPECT_EQ(parse_builder("binned"), Builder::BinnedSah);
    EXPECT_THROW((void)parse_structure("kdtree?"), Error);
    EXPECT_THROW((void)parse_builder(""), Error);
}


// build_accel reports 0 first and 1 last, never going back; the top-down
// SAH builders report the references placed in leaves along the way, the
// others only the ends (and the tree's end at 0.9).
TEST(BvhBuild, BuildAccelReportsProgressFromZeroToOne) {
    const SceneGeometry geometry = test::make_triangle_soup(20000, 7, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f);
    for (Builder builder : {Builder::BinnedSah, Builder::SweepSah, Builder::Sbvh, Builder::Lbvh30, Builder::Ploc}) {
        for (Structure structure : {Structure::Bvh, Structure::KdTree}) {
            if (structure == Structure::KdTree && builder != Builder::BinnedSah) continue;
            SCOPED_TRACE(to_string(builder) + " " + to_string(structure));
            std::vector<double> seen;
            const BuildOptions options{.structure = structure, .builder = builder, .threads = 2};
            const auto accel = build_accel(geometry, options, [&](double f) { seen.push_back(f); });
            ASSERT_GE(seen.size(), 2u);
            EXPECT_EQ(seen.front(), 0.0);
            EXPECT_EQ(seen.back(), 1.0);
            EXPECT_TRUE(std::is_sorted(seen.begin(), seen.end()));
            const bool counts_leaves = structure == Structure::Bvh &&
                                       (builder == Builder::BinnedSah || builder == Builder::SweepSah || builder == Builder::Sbvh);
            const auto between = std::count_if(seen.begin(), seen.end(), [](double f) { return f > 0.0 && f < 0.9; });
            if (counts_leaves) EXPECT_GE(between, 10) << "leaves placed should move the bar";
            else EXPECT_EQ(between, 0);
        }
    }
}

}  // namespace
}  // namespace rf
