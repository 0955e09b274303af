// Full-sweep SAH builder, SBVH builder and the reinsertion optimizer:
// structural invariants of the canonical BVH (relaxed for SBVH, whose leaves
// reference clipped triangle pieces), the depth limit, determinism across
// thread counts, traversal against brute force, and SAH quality relations;
// the pinned output of the three top-down SAH builders (binned included).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/sbvh.h"
#include "accel/bvh/builders/sweep_sah.h"
#include "accel/bvh/optimize/reinsertion.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "bvh_hash.h"
#include "bvh_invariants.h"
#include "core/parallel.h"
#include "rayforge/accel/accel.h"

namespace rf {
namespace {

using test::check_bvh;
using test::identical;
using test::Refs;
using test::same_box;
using test::TreeShape;

// SBVH coverage: every point of every triangle lies in the box of at least
// one leaf that references it (sampled; child boxes lie inside their parents,
// which check_bvh verifies, so a ray reaching the point reaches the leaf).
void check_coverage(const Bvh& bvh, std::span<const Triangle> triangles, uint32_t seed) {
    std::vector<std::vector<Box3f>> leaf_boxes(triangles.size());
    for (const BvhNode& node : bvh.nodes) {
        if (!node.is_leaf()) continue;
        for (uint32_t s = node.first; s < node.first + node.count; ++s) {
            leaf_boxes[bvh.prim_indices[s]].push_back(node.bounds);
        }
    }
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    size_t missing = 0;
    for (size_t t = 0; t < triangles.size(); ++t) {
        const Triangle& tri = triangles[t];
        for (int k = 0; k < 8; ++k) {
            // In double, so the point really lies on the triangle (up to ~1e-16 relative).
            double b1 = unit(rng), b2 = unit(rng);
            if (b1 + b2 > 1.0) { b1 = 1.0 - b1; b2 = 1.0 - b2; }
            if (k < 3) { b1 = k == 1 ? 1.0 : 0.0; b2 = k == 2 ? 1.0 : 0.0; }
            double p[3];
            for (int a = 0; a < 3; ++a) p[a] = tri.v0[a] * (1.0 - b1 - b2) + tri.v1[a] * b1 + tri.v2[a] * b2;
            const bool covered = std::any_of(leaf_boxes[t].begin(), leaf_boxes[t].end(), [&](const Box3f& b) {
                for (int a = 0; a < 3; ++a) {
                    // The weights' rounding (about 1e-16), far below a float ulp.
                    const double slack = 1e-12 * (1.0 + std::fabs(p[a]));
                    if (p[a] < b.lo[a] - slack || p[a] > b.hi[a] + slack) return false;
                }
                return true;
            });
            missing += covered ? 0 : 1;
        }
    }
    EXPECT_EQ(missing, 0u) << "triangle points outside every leaf box of their triangle";
}

// Unit triangles at x = 1.09^i (bvh_build_test.cpp): lopsided splits that
// would make a chain over 100 levels deep without the depth limit.
SceneGeometry make_geometric_row(int count) {
    SceneGeometry g;
    float x = 1.0f;
    for (int i = 0; i < count; ++i, x *= 1.09f) {
        test::append(g, {Vec3f(x, 0, 0), Vec3f(x, 1, 0), Vec3f(x, 0, 1)});
    }
    return g;
}

// Long thin triangles along the box diagonals: their boxes overlap almost
// everywhere, which object splits cannot fix and spatial splits can.
SceneGeometry make_thin_diagonals(int count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-10.0f, 10.0f);
    SceneGeometry g;
    for (int i = 0; i < count; ++i) {
        const Vec3f a(u(rng), u(rng), u(rng));
        const Vec3f dir = (i % 2) ? Vec3f(1.0f, 1.0f, 0.3f) : Vec3f(-1.0f, 1.0f, -0.2f);
        const Vec3f b = a + dir * 12.0f;
        test::append(g, {a, b, a + Vec3f(0.0f, 0.0f, 0.05f)});
    }
    g.normal_matrices.push_back(Affine3f::identity());
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
    scenes.push_back({"huge", test::make_triangle_soup(2000, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f)});
    scenes.push_back({"diagonals", make_thin_diagonals(1500, 4)});
    scenes.push_back({"geometric", make_geometric_row(900)});
    SceneGeometry same;
    for (int i = 0; i < 100; ++i) test::append(same, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    scenes.push_back({"identical", std::move(same)});
    SceneGeometry points;
    for (int i = 0; i < 50; ++i) test::append(points, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    scenes.push_back({"points", std::move(points)});
    return scenes;
}

// The ray mix of bvh_traversal_test.cpp: random, aimed at triangles (mostly
// hits), zero direction components, and [tmin, tmax] limits.
using test::make_rays;

void compare_with_brute_force(const SceneGeometry& g, const BuildOptions& options, size_t ray_count, uint32_t seed) {
    const auto accel = build_accel(g, options);
    const BruteForceAccel brute(g);
    size_t hits = 0;
    for (const Ray& ray : make_rays(g, ray_count, seed)) {
        const Hit expected = brute.intersect(ray);
        const Hit got = accel->intersect(ray);
        ASSERT_EQ(got.found(), expected.found());
        EXPECT_EQ(accel->occluded(ray), expected.found());
        if (!expected.found()) continue;
        ++hits;
        if (got.prim != expected.prim) {  // another triangle at (almost) the same distance
            EXPECT_NEAR(got.t, expected.t, 1e-5f * std::fabs(expected.t));
        } else {
            EXPECT_EQ(got.t, expected.t);
        }
        EXPECT_GE(got.t, ray.tmin);
        EXPECT_LE(got.t, ray.tmax);
    }
    EXPECT_GT(hits, ray_count / 10);
}

std::vector<NamedScene> traversal_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(3000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(3), 3.0f)});
    scenes.push_back({"nasty", test::make_nasty_geometry(4)});
    scenes.push_back({"far", test::make_triangle_soup(2000, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f)});
    scenes.push_back({"huge", test::make_triangle_soup(2000, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f)});
    scenes.push_back({"diagonals", make_thin_diagonals(1500, 5)});
    return scenes;
}

// --- Full sweep SAH -------------------------------------------------------

TEST(SweepSah, InvariantsHoldForScenesLeafSizesAndThreads) {
    for (const NamedScene& scene : test_scenes()) {
        for (int leaf_size : {1, 4, 16}) {
            for (int threads : {1, 2}) {
                SCOPED_TRACE(scene.name + " leaf " + std::to_string(leaf_size) + " threads " + std::to_string(threads));
                const Bvh bvh = build_bvh(scene.geometry.triangles, BuildOptions{.builder = Builder::SweepSah,
                                                                                  .threads = threads,
                                                                                  .max_leaf_size = leaf_size});
                check_bvh(bvh, scene.geometry.triangles, leaf_size);
                EXPECT_TRUE(std::isfinite(bvh.sah_cost()));
            }
        }
    }
}

// Coordinates so large that every box area overflows to infinity: all SAH
// costs tie, every split peels off one triangle, and only the depth limit
// stops a chain hundreds of levels deep.
SceneGeometry make_overflowing_soup() {
    return test::make_triangle_soup(600, 3, {Vec3f(-1e25f), Vec3f(1e25f)}, 1e24f);
}

TEST(SweepSah, DepthStaysWithinLimitOnPathologicalInput) {
    const SceneGeometry row = make_geometric_row(900);
    const SceneGeometry overflow = make_overflowing_soup();
    for (int leaf_size : {1, 4}) {
        const BvhBuildConfig config{.max_leaf_size = leaf_size};
        check_bvh(build_sweep_sah(row.triangles, config), row.triangles, leaf_size);
        const TreeShape shape = check_bvh(build_sweep_sah(overflow.triangles, config), overflow.triangles, leaf_size);
        EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        EXPECT_GT(shape.max_depth, 50);  // the input really is lopsided
    }
}

TEST(SweepSah, SameTreeForEveryThreadCount) {
    // Large enough for parallel sorts, axis tasks and subtree tasks.
    const SceneGeometry soup = test::make_triangle_soup(80000, 5, {Vec3f(-100.0f), Vec3f(100.0f)}, 1.0f);
    const Bvh one = build_bvh(soup.triangles, BuildOptions{.builder = Builder::SweepSah, .threads = 1});
    const Bvh two = build_bvh(soup.triangles, BuildOptions{.builder = Builder::SweepSah, .threads = 2});
    const Bvh all = build_bvh(soup.triangles, BuildOptions{.builder = Builder::SweepSah, .threads = 0});
    EXPECT_TRUE(identical(one, two));
    EXPECT_TRUE(identical(one, all));
    check_bvh(one, soup.triangles, 4);
}

TEST(SweepSah, SahNoWorseThanBinned) {
    for (const NamedScene& scene : test_scenes()) {
        if (scene.name == "identical" || scene.name == "points" || scene.name == "geometric") continue;
        SCOPED_TRACE(scene.name);
        const double binned =
            build_binned_sah(scene.geometry.triangles, BvhBuildConfig{}, BinnedSahOptions{}).sah_cost();
        const double sweep = build_sweep_sah(scene.geometry.triangles, BvhBuildConfig{}).sah_cost();
        EXPECT_LE(sweep, binned * 1.02);
    }
}

TEST(SweepSah, MatchesBruteForce) {
    for (const NamedScene& scene : traversal_scenes()) {
        SCOPED_TRACE(scene.name);
        compare_with_brute_force(scene.geometry, BuildOptions{.builder = Builder::SweepSah, .max_leaf_size = 2}, 1500, 11);
    }
}

TEST(SweepSah, EmptyAndSingleTriangle) {
    EXPECT_TRUE(build_sweep_sah({}, BvhBuildConfig{}).nodes.empty());
    const Triangle tri{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)};
    const Bvh one = build_sweep_sah(std::span<const Triangle>(&tri, 1), BvhBuildConfig{});
    ASSERT_EQ(one.nodes.size(), 1u);
    EXPECT_EQ(one.nodes[0].count, 1u);
    EXPECT_TRUE(same_box(one.nodes[0].bounds, tri.bounds()));
}

// --- SBVH -----------------------------------------------------------------

TEST(Sbvh, InvariantsHoldForScenesLeafSizesAndThreads) {
    for (const NamedScene& scene : test_scenes()) {
        for (int leaf_size : {1, 4, 16}) {
            for (int threads : {1, 2}) {
                SCOPED_TRACE(scene.name + " leaf " + std::to_string(leaf_size) + " threads " + std::to_string(threads));
                const Bvh bvh = build_bvh(scene.geometry.triangles, BuildOptions{.builder = Builder::Sbvh,
                                                                                  .threads = threads,
                                                                                  .max_leaf_size = leaf_size});
                check_bvh(bvh, scene.geometry.triangles, leaf_size, Refs::SpatialSplit);
                check_coverage(bvh, scene.geometry.triangles, 7);
                EXPECT_LE(bvh.prim_indices.size(), 2 * scene.geometry.triangles.size());  // the reference budget
                EXPECT_TRUE(std::isfinite(bvh.sah_cost()));
            }
        }
    }
}

TEST(Sbvh, DepthStaysWithinLimitOnPathologicalInput) {
    const SceneGeometry row = make_geometric_row(900);
    const SceneGeometry overflow = make_overflowing_soup();
    for (int leaf_size : {1, 4}) {
        const BvhBuildConfig config{.max_leaf_size = leaf_size};
        check_bvh(build_sbvh(row.triangles, config, SbvhOptions{}), row.triangles, leaf_size, Refs::SpatialSplit);
        const TreeShape shape = check_bvh(build_sbvh(overflow.triangles, config, SbvhOptions{}), overflow.triangles,
                                          leaf_size, Refs::SpatialSplit);
        EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        EXPECT_GT(shape.max_depth, 50);
    }
}

TEST(Sbvh, SameTreeForEveryThreadCount) {
    const SceneGeometry soup = test::make_triangle_soup(12000, 6, {Vec3f(-40.0f), Vec3f(40.0f)}, 3.0f);
    const Bvh one = build_bvh(soup.triangles, BuildOptions{.builder = Builder::Sbvh, .threads = 1});
    const Bvh two = build_bvh(soup.triangles, BuildOptions{.builder = Builder::Sbvh, .threads = 2});
    const Bvh all = build_bvh(soup.triangles, BuildOptions{.builder = Builder::Sbvh, .threads = 0});
    EXPECT_GT(one.prim_indices.size(), soup.triangles.size());  // spatial splits happened
    EXPECT_TRUE(identical(one, two));
    EXPECT_TRUE(identical(one, all));
}

// Long thin triangles among a dense soup: the spare references go mostly to
// the subtrees of the long ones and flow on from left to right subtrees in
// the sequential part; the tree must not depend on the thread count, and the
// budget must hold.
TEST(Sbvh, BudgetSharingIsDeterministicAndBounded) {
    SceneGeometry mixed = test::make_triangle_soup(8000, 11, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f);
    const SceneGeometry diagonals = make_thin_diagonals(600, 12);
    mixed.triangles.insert(mixed.triangles.end(), diagonals.triangles.begin(), diagonals.triangles.end());
    const Bvh one = build_bvh(mixed.triangles, BuildOptions{.builder = Builder::Sbvh, .threads = 1});
    const Bvh two = build_bvh(mixed.triangles, BuildOptions{.builder = Builder::Sbvh, .threads = 2});
    const Bvh all = build_bvh(mixed.triangles, BuildOptions{.builder = Builder::Sbvh, .threads = 0});
    EXPECT_TRUE(identical(one, two));
    EXPECT_TRUE(identical(one, all));
    check_bvh(one, mixed.triangles, 4, Refs::SpatialSplit);
    EXPECT_GT(one.prim_indices.size(), mixed.triangles.size());
    EXPECT_LE(one.prim_indices.size(), 2 * mixed.triangles.size());
    EXPECT_LT(one.sah_cost(), build_sweep_sah(mixed.triangles, BvhBuildConfig{}).sah_cost());
}

TEST(Sbvh, LowestSahWhereSpatialSplitsMatter) {
    const SceneGeometry diagonals = make_thin_diagonals(3000, 8);
    const double binned = build_binned_sah(diagonals.triangles, BvhBuildConfig{}, BinnedSahOptions{}).sah_cost();
    const double sweep = build_sweep_sah(diagonals.triangles, BvhBuildConfig{}).sah_cost();
    const double sbvh = build_sbvh(diagonals.triangles, BvhBuildConfig{}, SbvhOptions{}).sah_cost();
    EXPECT_LT(sbvh, sweep * 0.9);
    EXPECT_LT(sbvh, binned * 0.9);
    // Elsewhere it is still no worse than the sweep (its object splits are the same sweep).
    for (const NamedScene& scene : test_scenes()) {
        if (scene.name == "identical" || scene.name == "points") continue;
        SCOPED_TRACE(scene.name);
        const double s = build_sweep_sah(scene.geometry.triangles, BvhBuildConfig{}).sah_cost();
        EXPECT_LE(build_sbvh(scene.geometry.triangles, BvhBuildConfig{}, SbvhOptions{}).sah_cost(), s * 1.001);
    }
}

TEST(Sbvh, AlphaOneDisablesSpatialSplits) {
    const SceneGeometry diagonals = make_thin_diagonals(1000, 9);
    const Bvh sbvh = build_sbvh(diagonals.triangles, BvhBuildConfig{}, SbvhOptions{.alpha = 1.0f});
    EXPECT_EQ(sbvh.prim_indices.size(), diagonals.triangles.size());
    EXPECT_TRUE(identical(sbvh, build_sweep_sah(diagonals.triangles, BvhBuildConfig{})));
}

TEST(Sbvh, MatchesBruteForce) {
    for (const NamedScene& scene : traversal_scenes()) {
        SCOPED_TRACE(scene.name);
        compare_with_brute_force(scene.geometry, BuildOptions{.builder = Builder::Sbvh, .max_leaf_size = 2}, 1500, 12);
    }
}

TEST(Sbvh, EmptyAndSingleTriangle) {
    EXPECT_TRUE(build_sbvh({}, BvhBuildConfig{}, SbvhOptions{}).nodes.empty());
    const Triangle tri{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)};
    const Bvh one = build_sbvh(std::span<const Triangle>(&tri, 1), BvhBuildConfig{}, SbvhOptions{});
    ASSERT_EQ(one.nodes.size(), 1u);
    EXPECT_EQ(one.prim_indices, std::vector<uint32_t>{0});
    EXPECT_TRUE(same_box(one.nodes[0].bounds, tri.bounds()));
}

// --- Binned SAH: the root split against a plain reference ---------------

// The root split of Wald's binned SAH computed the plain way: every
// primitive's centroid binned, every boundary of every bin on every usable
// axis evaluated in order, the first cheapest kept. Returns the triangles
// that go left (empty when no boundary separates them).
std::vector<uint32_t> reference_left_of_root(std::span<const Triangle> tris, int bins) {
    const size_t n = tris.size();
    std::vector<Box3f> boxes(n);
    std::vector<Vec3f> centroids(n);
    Box3f centroid_bounds;
    for (size_t i = 0; i < n; ++i) {
        boxes[i] = tris[i].bounds();
        centroids[i] = (boxes[i].lo + boxes[i].hi) * 0.5f;
        centroid_bounds.extend(centroids[i]);
    }
    float best_cost = 0.0f;
    int best_axis = -1, best_bin = 0;
    std::vector<int> bin(n);
    for (int axis = 0; axis < 3; ++axis) {
        const float extent = centroid_bounds.hi[axis] - centroid_bounds.lo[axis];
        const float scale = static_cast<float>(bins) * (1.0f - 0x1p-20f) / extent;
        if (!(extent > 0.0f) || !std::isfinite(scale)) continue;
        for (size_t i = 0; i < n; ++i) {
            const float x = (centroids[i][axis] - centroid_bounds.lo[axis]) * scale;
            bin[i] = static_cast<int>(std::min(std::max(x, 0.0f), static_cast<float>(bins - 1)));
        }
        for (int b = 1; b < bins; ++b) {
            Box3f left, right;
            uint32_t left_count = 0, right_count = 0;
            for (size_t i = 0; i < n; ++i) {
                if (bin[i] < b) {
                    left.extend(boxes[i]);
                    ++left_count;
                } else {
                    right.extend(boxes[i]);
                    ++right_count;
                }
            }
            if (left_count == 0 || right_count == 0) continue;
            const float cost = left.surface_area() * static_cast<float>(left_count) +
                               right.surface_area() * static_cast<float>(right_count);
            if (best_axis < 0 || cost < best_cost) {
                best_cost = cost;
                best_axis = axis;
                best_bin = b;
            }
        }
    }
    std::vector<uint32_t> left;
    if (best_axis < 0) return left;
    const float scale = static_cast<float>(bins) * (1.0f - 0x1p-20f) /
                        (centroid_bounds.hi[best_axis] - centroid_bounds.lo[best_axis]);
    for (size_t i = 0; i < n; ++i) {
        const float x = (centroids[i][best_axis] - centroid_bounds.lo[best_axis]) * scale;
        if (static_cast<int>(std::min(std::max(x, 0.0f), static_cast<float>(bins - 1))) < best_bin) {
            left.push_back(static_cast<uint32_t>(i));
        }
    }
    return left;
}

TEST(BinnedSah, RootSplitMatchesPlainBinning) {
    // Node sizes around the builder's shortcuts (two primitives, sparse bins
    // up to 16, bit-mask partition up to 64, the general path beyond), and
    // bin counts whose non-empty-bin masks span one to four words.
    for (const size_t count : {2u, 3u, 5u, 16u, 17u, 40u, 64u, 65u, 200u, 700u}) {
        for (const int bins : {2, 4, 16, 100, 256}) {
            for (uint32_t seed = 1; seed <= 3; ++seed) {
                SCOPED_TRACE(std::to_string(count) + " triangles, " + std::to_string(bins) + " bins, seed " +
                             std::to_string(seed));
                const SceneGeometry soup =
                    test::make_triangle_soup(count, 100 + seed, {Vec3f(-10.0f), Vec3f(10.0f)}, 2.0f);
                const Bvh bvh = build_binned_sah(soup.triangles, BvhBuildConfig{.max_leaf_size = 1},
                                                 BinnedSahOptions{.bin_count = bins});
                const std::vector<uint32_t> expected = reference_left_of_root(soup.triangles, bins);
                ASSERT_FALSE(expected.empty());
                ASSERT_FALSE(bvh.nodes[0].is_leaf());
                // Depth-first order: the left subtree's triangles come first.
                std::vector<uint32_t> left(bvh.prim_indices.begin(),
                                           bvh.prim_indices.begin() + static_cast<ptrdiff_t>(expected.size()));
                std::sort(left.begin(), left.end());
                EXPECT_EQ(left, expected);
            }
        }
    }
}

// --- Pinned output of the top-down SAH builders ----------------------------

// The binned, full-sweep and SBVH builders' trees over scenes that reach
// every path of the shared top-down skeleton (SAH leaves, median and depth
// fallbacks, parallel binning and subtree tasks, spatial splits and the
// reference budget), for leaf sizes, bin counts and SAH costs, on 1 and 2
// threads. The hashes were taken before the builders shared the skeleton
// (top_down_sah.h); RF_PRINT_SAH_BVH_HASHES prints them for re-pinning
// after an intended change of a builder.
TEST(SahBuilders, OutputIsPinned) {
    const bool print = std::getenv("RF_PRINT_SAH_BVH_HASHES") != nullptr;
    const std::vector<uint64_t> expected = {
0xfbb5fe70abfd9bc7ull,  // soup binned leaf 4 bins 16 costs 1/1
        0x194d987dc24cc82bull,  // soup binned leaf 1 bins 16 costs 1/1
        0x4d56f96cef87094dull,  // soup binned leaf 8 bins 4 costs 1.3/0.7
        0xc4a1ed52f607a823ull,  // soup sweep leaf 4 bins 16 costs 1/1
        0xa5852eb19ddf19f5ull,  // soup sweep leaf 1 bins 16 costs 1/1
        0x65c84f1cfb309165ull,  // soup sweep leaf 8 bins 4 costs 1.3/0.7
        0x9b768d4468270335ull,  // soup sbvh leaf 4 bins 16 costs 1/1
        0xa6f7930f15b68474ull,  // soup sbvh leaf 1 bins 16 costs 1/1
        0x4e2e286ef631e4afull,  // soup sbvh leaf 8 bins 4 costs 1.3/0.7
        0xd5e1afb33d6d1dedull,  // sphere binned leaf 4 bins 16 costs 1/1
        0x6cdc8a372e1c0801ull,  // sphere binned leaf 1 bins 16 costs 1/1
        0xbb01bcdd9768b227ull,  // sphere binned leaf 8 bins 4 costs 1.3/0.7
        0xf0a0b8560b7e1ec3ull,  // sphere sweep leaf 4 bins 16 costs 1/1
        0xe93c0b56d928741dull,  // sphere sweep leaf 1 bins 16 costs 1/1
        0x3c70897e2809b981ull,  // sphere sweep leaf 8 bins 4 costs 1.3/0.7
        0x075553c7490c812bull,  // sphere sbvh leaf 4 bins 16 costs 1/1
        0x55a92d35f75f4313ull,  // sphere sbvh leaf 1 bins 16 costs 1/1
        0xfe495c459fee2598ull,  // sphere sbvh leaf 8 bins 4 costs 1.3/0.7
        0x6cae68ed1e28abc2ull,  // nasty binned leaf 4 bins 16 costs 1/1
        0x6519523cc08cfa12ull,  // nasty binned leaf 1 bins 16 costs 1/1
        0xb771d5e8551fdd57ull,  // nasty binned leaf 8 bins 4 costs 1.3/0.7
        0x1ee0b0139e6df163ull,  // nasty sweep leaf 4 bins 16 costs 1/1
        0x991fd4b1460ac342ull,  // nasty sweep leaf 1 bins 16 costs 1/1
        0xa6afc7db69ac5706ull,  // nasty sweep leaf 8 bins 4 costs 1.3/0.7
        0xd88d91d49282203cull,  // nasty sbvh leaf 4 bins 16 costs 1/1
        0x7b53c326b31b141aull,  // nasty sbvh leaf 1 bins 16 costs 1/1
        0xf2171d86192cb20full,  // nasty sbvh leaf 8 bins 4 costs 1.3/0.7
        0x5be63097a26a9de4ull,  // far binned leaf 4 bins 16 costs 1/1
        0xb1b256c941d9cdeaull,  // far binned leaf 1 bins 16 costs 1/1
        0xe1722cdb969a5a6cull,  // far binned leaf 8 bins 4 costs 1.3/0.7
        0x25c8f46bdf9f28bcull,  // far sweep leaf 4 bins 16 costs 1/1
        0xeb94f61066b0007aull,  // far sweep leaf 1 bins 16 costs 1/1
        0x95dc48178c38d6b4ull,  // far sweep leaf 8 bins 4 costs 1.3/0.7
        0x25c8f46bdf9f28bcull,  // far sbvh leaf 4 bins 16 costs 1/1
        0xeb94f61066b0007aull,  // far sbvh leaf 1 bins 16 costs 1/1
        0x95dc48178c38d6b4ull,  // far sbvh leaf 8 bins 4 costs 1.3/0.7
        0xb2c5a7b1787557bfull,  // huge binned leaf 4 bins 16 costs 1/1
        0xaa5dc1987c15966bull,  // huge binned leaf 1 bins 16 costs 1/1
        0xb4b08ed75256d658ull,  // huge binned leaf 8 bins 4 costs 1.3/0.7
        0x1ee82fc37e03e7f3ull,  // huge sweep leaf 4 bins 16 costs 1/1
        0x4ed65c076f8e1258ull,  // huge sweep leaf 1 bins 16 costs 1/1
        0xac49dbafc7adfd33ull,  // huge sweep leaf 8 bins 4 costs 1.3/0.7
        0x1ee82fc37e03e7f3ull,  // huge sbvh leaf 4 bins 16 costs 1/1
        0x4ed65c076f8e1258ull,  // huge sbvh leaf 1 bins 16 costs 1/1
        0xac49dbafc7adfd33ull,  // huge sbvh leaf 8 bins 4 costs 1.3/0.7
        0x197ae41fb7531fe6ull,  // diagonals binned leaf 4 bins 16 costs 1/1
        0xf9f060e7e677b21bull,  // diagonals binned leaf 1 bins 16 costs 1/1
        0x3041390ebd3890daull,  // diagonals binned leaf 8 bins 4 costs 1.3/0.7
        0x6cad6a67ff73012cull,  // diagonals sweep leaf 4 bins 16 costs 1/1
        0x640d72e38b1fdbbdull,  // diagonals sweep leaf 1 bins 16 costs 1/1
        0x65cdeb9106952860ull,  // diagonals sweep leaf 8 bins 4 costs 1.3/0.7
        0xf2361db736ae35fbull,  // diagonals sbvh leaf 4 bins 16 costs 1/1
        0x84beb144407532c6ull,  // diagonals sbvh leaf 1 bins 16 costs 1/1
        0x87d9b288da55a0e0ull,  // diagonals sbvh leaf 8 bins 4 costs 1.3/0.7
        0xbc8981ecf353ba1eull,  // geometric binned leaf 4 bins 16 costs 1/1
        0xe78705975b7e98abull,  // geometric binned leaf 1 bins 16 costs 1/1
        0x69b4067616c1280full,  // geometric binned leaf 8 bins 4 costs 1.3/0.7
        0x34987ff88e2d2eb3ull,  // geometric sweep leaf 4 bins 16 costs 1/1
        0xb776666297c136a1ull,  // geometric sweep leaf 1 bins 16 costs 1/1
        0x83c9d51edda37234ull,  // geometric sweep leaf 8 bins 4 costs 1.3/0.7
        0x34987ff88e2d2eb3ull,  // geometric sbvh leaf 4 bins 16 costs 1/1
        0xb776666297c136a1ull,  // geometric sbvh leaf 1 bins 16 costs 1/1
        0x83c9d51edda37234ull,  // geometric sbvh leaf 8 bins 4 costs 1.3/0.7
        0x665011ee0826191cull,  // identical binned leaf 4 bins 16 costs 1/1
        0xdb76a114c507f2b4ull,  // identical binned leaf 1 bins 16 costs 1/1
        0xdf34ade75dec735cull,  // identical binned leaf 8 bins 4 costs 1.3/0.7
        0xe3c5e8f342ddf45cull,  // identical sweep leaf 4 bins 16 costs 1/1
        0xcef37c991b004b54ull,  // identical sweep leaf 1 bins 16 costs 1/1
        0x4c1ea50edc064169ull,  // identical sweep leaf 8 bins 4 costs 1.3/0.7
        0x47f67ed16c8c4019ull,  // identical sbvh leaf 4 bins 16 costs 1/1
        0x45ca52920a6ca63aull,  // identical sbvh leaf 1 bins 16 costs 1/1
        0xbefda87a60121da8ull,  // identical sbvh leaf 8 bins 4 costs 1.3/0.7
        0xc9d8c4347ce484f5ull,  // points binned leaf 4 bins 16 costs 1/1
        0x19e0d3ce1fcb5f72ull,  // points binned leaf 1 bins 16 costs 1/1
        0xba8827cfa8a4940dull,  // points binned leaf 8 bins 4 costs 1.3/0.7
        0x1ab5da3ac835aafbull,  // points sweep leaf 4 bins 16 costs 1/1
        0x9e80e3819e9ebd12ull,  // points sweep leaf 1 bins 16 costs 1/1
        0x2673102cd6b44fb3ull,  // points sweep leaf 8 bins 4 costs 1.3/0.7
        0x1ab5da3ac835aafbull,  // points sbvh leaf 4 bins 16 costs 1/1
        0x9e80e3819e9ebd12ull,  // points sbvh leaf 1 bins 16 costs 1/1
        0x2673102cd6b44fb3ull,  // points sbvh leaf 8 bins 4 costs 1.3/0.7
        0x3a0afa778e5e717full,  // overflow binned leaf 4 bins 16 costs 1/1
        0x0c445380f0a2f5beull,  // overflow binned leaf 1 bins 16 costs 1/1
        0xad5d918134cfceb8ull,  // overflow binned leaf 8 bins 4 costs 1.3/0.7
        0x769a71db2f483803ull,  // overflow sweep leaf 4 bins 16 costs 1/1
        0xb1685075fa6fcb24ull,  // overflow sweep leaf 1 bins 16 costs 1/1
        0xefd1813e5bfb58ecull,  // overflow sweep leaf 8 bins 4 costs 1.3/0.7
        0x769a71db2f483803ull,  // overflow sbvh leaf 4 bins 16 costs 1/1
        0xb1685075fa6fcb24ull,  // overflow sbvh leaf 1 bins 16 costs 1/1
        0xefd1813e5bfb58ecull,  // overflow sbvh leaf 8 bins 4 costs 1.3/0.7
        0x303675285c3d9c44ull,  // spatial soup binned leaf 4 bins 16 costs 1/1
        0x51bf6c33f9f5823aull,  // spatial soup binned leaf 1 bins 16 costs 1/1
        0xee4ae0a634214c23ull,  // spatial soup binned leaf 8 bins 4 costs 1.3/0.7
        0x75a77c115073a749ull,  // spatial soup sweep leaf 4 bins 16 costs 1/1
        0x55f92bd6e1b0fb95ull,  // spatial soup sweep leaf 1 bins 16 costs 1/1
        0x89e93830b2c26e2eull,  // spatial soup sweep leaf 8 bins 4 costs 1.3/0.7
        0x03e5121a39f3a354ull,  // spatial soup sbvh leaf 4 bins 16 costs 1/1
        0x597ab53ccceae22cull,  // spatial soup sbvh leaf 1 bins 16 costs 1/1
        0x6ff93ed282b8a4d4ull,  // spatial soup sbvh leaf 8 bins 4 costs 1.3/0.7
        0xe08f234c14fc5822ull,  // large soup binned leaf 4 bins 16 costs 1/1
        0x3236185675c63245ull,  // large soup binned leaf 1 bins 16 costs 1/1
        0x174c78f608672c10ull,  // large soup binned leaf 8 bins 4 costs 1.3/0.7
        0x4507bfc3f23c498dull,  // large soup sweep leaf 4 bins 16 costs 1/1
        0xf88cac0eccc014abull,  // large soup sweep leaf 1 bins 16 costs 1/1
        0xcbd4df3faf87c71full,  // large soup sweep leaf 8 bins 4 costs 1.3/0.7
    };
    std::vector<NamedScene> scenes = test_scenes();
    scenes.push_back({"overflow", make_overflowing_soup()});
    scenes.push_back({"spatial soup", test::make_triangle_soup(12000, 6, {Vec3f(-40.0f), Vec3f(40.0f)}, 3.0f)});
    scenes.push_back({"large soup", test::make_triangle_soup(80000, 5, {Vec3f(-100.0f), Vec3f(100.0f)}, 1.0f)});
    struct Variant {
        int leaf, bins;
        SahCosts sah;
    };
    const Variant variants[] = {{4, 16, {1.0f, 1.0f}}, {1, 16, {1.0f, 1.0f}}, {8, 4, {1.3f, 0.7f}}};
    size_t k = 0;
    for (const NamedScene& scene : scenes) {
        for (const Builder builder : {Builder::BinnedSah, Builder::SweepSah, Builder::Sbvh}) {
            if (builder == Builder::Sbvh && scene.name == "large soup") continue;  // slow, and like "spatial soup"
            for (const Variant& v : variants) {
                const std::string what = scene.name + " " + to_string(builder) + " leaf " + std::to_string(v.leaf) +
                                         " bins " + std::to_string(v.bins);
                for (const int threads : {1, 2}) {
                    const BuildOptions options{.builder = builder, .threads = threads, .max_leaf_size = v.leaf,
                                               .sah = v.sah, .binned = {.bin_count = v.bins}};
                    const uint64_t h = test::bvh_hash(build_bvh(scene.geometry.triangles, options));
                    if (print && threads == 1) {
                        std::printf("        0x%016llxull,  // %s %s leaf %d bins %d costs %g/%g\n",
                                    static_cast<unsigned long long>(h), scene.name.c_str(),
                                    to_string(builder).c_str(), v.leaf, v.bins, v.sah.traversal, v.sah.intersection);
                    }
                    if (k < expected.size()) EXPECT_EQ(expected[k], h) << what << " threads " << threads;
                }
                ++k;
            }
        }
    }
    EXPECT_EQ(k, expected.size());
}

// --- Reinsertion ----------------------------------------------------------

TEST(Reinsertion, NeverIncreasesSahAndKeepsInvariants) {
    for (const NamedScene& scene : test_scenes()) {
        for (const Builder builder : {Builder::BinnedSah, Builder::SweepSah, Builder::Sbvh}) {
            SCOPED_TRACE(scene.name + " " + to_string(builder));
            const BvhBuildConfig config{.max_leaf_size = 2};
            const std::span<const Triangle> tris = scene.geometry.triangles;
            Bvh bvh = builder == Builder::BinnedSah  ? build_binned_sah(tris, config, BinnedSahOptions{})
                      : builder == Builder::SweepSah ? build_sweep_sah(tris, config)
                                                     : build_sbvh(tris, config, SbvhOptions{});
            const double before = bvh.sah_cost();
            const size_t leaves = bvh.leaf_count();
            optimize_reinsertion(bvh, tris, config.sah, ReinsertionOptions{});
            EXPECT_LE(bvh.sah_cost(), before);
            EXPECT_EQ(bvh.leaf_count(), leaves);
            check_bvh(bvh, tris, 2, builder == Builder::Sbvh ? Refs::SpatialSplit : Refs::Once);
        }
    }
}

TEST(Reinsertion, LowersSahOfPoorTree) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(5));
    // An LBVH (Morton order, no SAH above the leaves) leaves much to gain.
    const BuildOptions lbvh{.builder = Builder::Lbvh30};
    Bvh bvh = build_bvh(sphere.triangles, lbvh);
    const double before = bvh.sah_cost();
    optimize_reinsertion(bvh, sphere.triangles, SahCosts{}, ReinsertionOptions{});
    const double after = bvh.sah_cost();
    EXPECT_LT(after, before * 0.97) << before << " -> " << after;
    check_bvh(bvh, sphere.triangles, 4);

    // Two bins per axis: spatial-median splits, a poor tree too.
    Bvh binned = build_binned_sah(sphere.triangles, BvhBuildConfig{}, BinnedSahOptions{.bin_count = 2});
    const double binned_before = binned.sah_cost();
    optimize_reinsertion(binned, sphere.triangles, SahCosts{}, ReinsertionOptions{});
    EXPECT_LT(binned.sah_cost(), binned_before);

    // More batches never do worse than one.
    Bvh once = build_bvh(sphere.triangles, lbvh);
    optimize_reinsertion(once, sphere.triangles, SahCosts{}, ReinsertionOptions{.iterations = 1});
    EXPECT_LT(once.sah_cost(), before);
    EXPECT_LE(after, once.sah_cost());
}

TEST(Reinsertion, DepthStaysWithinLimit) {
    // A tree already close to the depth limit: reinsertion must not push it over.
    const SceneGeometry row = make_geometric_row(900);
    Bvh bvh = build_binned_sah(row.triangles, BvhBuildConfig{.max_leaf_size = 1}, BinnedSahOptions{.bin_count = 2});
    const double before = bvh.sah_cost();
    optimize_reinsertion(bvh, row.triangles, SahCosts{}, ReinsertionOptions{.iterations = 20});
    EXPECT_LE(bvh.sah_cost(), before);
    check_bvh(bvh, row.triangles, 1);
    // A tree at the depth limit whose costs are all infinite stays valid.
    const SceneGeometry overflow = make_overflowing_soup();
    Bvh deep = build_sweep_sah(overflow.triangles, BvhBuildConfig{.max_leaf_size = 1});
    optimize_reinsertion(deep, overflow.triangles, SahCosts{}, ReinsertionOptions{});
    EXPECT_LE(check_bvh(deep, overflow.triangles, 1).max_depth, kBvhMaxDepth);
}

TEST(Reinsertion, SameTreeForEveryThreadCount) {
    const SceneGeometry soup = test::make_triangle_soup(30000, 11, {Vec3f(-50.0f), Vec3f(50.0f)}, 1.0f);
    const Bvh base = build_binned_sah(soup.triangles, BvhBuildConfig{}, BinnedSahOptions{.bin_count = 4});
    Bvh one = base, two = base, all = base;
    auto optimize_on = [&](int threads, Bvh& bvh) {
        parallel::with_threads(threads,
                               [&] { optimize_reinsertion(bvh, soup.triangles, SahCosts{}, ReinsertionOptions{}); });
    };
    optimize_on(1, one);
    optimize_on(2, two);
    optimize_on(0, all);
    EXPECT_TRUE(identical(one, two));
    EXPECT_TRUE(identical(one, all));
}

TEST(Reinsertion, MatchesBruteForce) {
    for (const NamedScene& scene : traversal_scenes()) {
        SCOPED_TRACE(scene.name);
        compare_with_brute_force(scene.geometry,
                                 BuildOptions{.binned = {.bin_count = 4}, .reinsertion = {.enabled = true}}, 1500, 13);
    }
}

TEST(Reinsertion, TinyTreesAreLeftAlone) {
    Bvh empty;
    optimize_reinsertion(empty, {}, SahCosts{}, ReinsertionOptions{});
    EXPECT_TRUE(empty.nodes.empty());
    const SceneGeometry three = test::make_triangle_soup(3, 12, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.2f);
    Bvh bvh = build_binned_sah(three.triangles, BvhBuildConfig{.max_leaf_size = 1}, BinnedSahOptions{});
    const Bvh before = bvh;
    optimize_reinsertion(bvh, three.triangles, SahCosts{}, ReinsertionOptions{});
    EXPECT_TRUE(identical(bvh, before));
}

}  // namespace
}  // namespace rf
