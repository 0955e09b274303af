// BVH traversal against the brute-force reference: closest hits, any hits,
// batches and counting variants over procedural scenes and awkward rays.
#include "trace/bvh_traversal.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/bvh_accel.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

using test::make_rays;

void expect_same_closest(const Hit& bvh, const Hit& brute, const Ray& ray) {
    ASSERT_EQ(bvh.found(), brute.found());
    if (!brute.found()) return;
    if (bvh.prim != brute.prim) {
        // Another triangle only at (almost) the same distance: shared edges,
        // duplicates, triangles lying in a box face.
        EXPECT_NEAR(bvh.t, brute.t, 1e-5f * std::fabs(brute.t)) << "bvh prim " << bvh.prim << " brute prim "
                                                                  << brute.prim;
    } else {
        EXPECT_EQ(bvh.t, brute.t);
        EXPECT_EQ(bvh.u, brute.u);
        EXPECT_EQ(bvh.v, brute.v);
    }
    EXPECT_GE(bvh.t, ray.tmin);
    EXPECT_LE(bvh.t, ray.tmax);
}

void compare_with_brute_force(const SceneGeometry& g, const BuildOptions& options, size_t ray_count,
                              uint32_t seed) {
    const auto bvh = build_accel(g, options);
    const BruteForceAccel brute(g);
    const std::vector<Ray> rays = make_rays(g, ray_count, seed);
    size_t hits = 0;
    for (const Ray& ray : rays) {
        const Hit expected = brute.intersect(ray);
        const Hit got = bvh->intersect(ray);
        expect_same_closest(got, expected, ray);
        EXPECT_EQ(bvh->occluded(ray), expected.found());
        EXPECT_EQ(brute.occluded(ray), expected.found());
        hits += expected.found();
    }
    // The rays must exercise both outcomes.
    EXPECT_GT(hits, ray_count / 5);
    EXPECT_LT(hits, ray_count);
}

TEST(BvhTraversal, MatchesBruteForceOnTriangleSoup) {
    const SceneGeometry soup = test::make_triangle_soup(4000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    for (int leaf : {1, 4, 8}) compare_with_brute_force(soup, BuildOptions{.max_leaf_size = leaf}, 1500, 1);
}

TEST(BvhTraversal, MatchesBruteForceOnTessellatedSphere) {
    compare_with_brute_force(test::to_geometry(test::make_icosphere(4), 3.0f), BuildOptions{}, 3000, 2);
}

TEST(BvhTraversal, MatchesBruteForceOnDegenerateAndThinTriangles) {
    compare_with_brute_force(test::make_nasty_geometry(4), BuildOptions{.max_leaf_size = 2}, 3000, 3);
}

TEST(BvhTraversal, MatchesBruteForceFarFromTheOrigin) {
    const SceneGeometry far = test::make_triangle_soup(2000, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    compare_with_brute_force(far, BuildOptions{}, 3000, 4);
    const SceneGeometry huge = test::make_triangle_soup(2000, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f);
    compare_with_brute_force(huge, BuildOptions{}, 3000, 5);
}

TEST(BvhTraversal, AxisAlignedRaysAlongBoxFaces) {
    // An axis-aligned grid of flat quads: rays with zero direction components
    // whose origins lie exactly on slab planes (0 * inf in the box test).
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(6));
    const auto bvh = build_accel(cube, BuildOptions{.max_leaf_size = 1});
    const BruteForceAccel brute(cube);
    int hits = 0;
    for (int i = -6; i <= 6; ++i) {
        for (int j = -6; j <= 6; ++j) {
            const float a = static_cast<float>(i) / 3.0f, b = static_cast<float>(j) / 3.0f;
            for (const Ray& ray : {Ray{Vec3f(a, b, -5.0f), 0.0f, Vec3f(0, 0, 1)},
                                   Ray{Vec3f(5.0f, a, b), 0.0f, Vec3f(-1, 0, 0)},
                                   Ray{Vec3f(a, -5.0f, b), 0.0f, Vec3f(0, 2, 0)},
                                   Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(0, 0, -1)}}) {
                const Hit expected = brute.intersect(ray);
                expect_same_closest(bvh->intersect(ray), expected, ray);
                EXPECT_EQ(bvh->occluded(ray), expected.found());
                hits += expected.found();
            }
        }
    }
    EXPECT_GT(hits, 100);
}

TEST(BvhTraversal, EmptySceneAlwaysMisses) {
    const SceneGeometry empty;
    const auto bvh = build_accel(empty);
    const Ray ray{Vec3f(0.0f), 0.0f, Vec3f(0, 0, 1)};
    EXPECT_FALSE(bvh->intersect(ray).found());
    EXPECT_FALSE(bvh->occluded(ray));
    EXPECT_EQ(bvh->stats().node_count, 0u);
}

TEST(BvhTraversal, BatchesEqualSingleRays) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 24, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.5f);
    const std::vector<Ray> rays = make_rays(soup, 2000, 6);
    for (Structure structure : {Structure::Bvh, Structure::BruteForce}) {
        const auto accel = build_accel(soup, BuildOptions{.structure = structure});
        std::vector<Hit> hits(rays.size());
        std::vector<uint8_t> occluded(rays.size(), 7);
        accel->intersect(rays, hits);
        accel->occluded(rays, occluded);
        for (size_t i = 0; i < rays.size(); ++i) {
            const Hit single = accel->intersect(rays[i]);
            EXPECT_EQ(hits[i].prim, single.prim);
            EXPECT_EQ(hits[i].t, single.t);
            EXPECT_EQ(occluded[i], accel->occluded(rays[i]) ? 1 : 0);
        }
        std::vector<Hit> too_few(rays.size() - 1);
        EXPECT_THROW(accel->intersect(rays, too_few), Error);
        std::vector<uint8_t> too_many(rays.size() + 1);
        EXPECT_THROW(accel->occluded(rays, too_many), Error);
    }
}

TEST(BvhTraversal, CountingVariantGivesSameResultsAndCounts) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    const BvhAccel accel(sphere, build_bvh(sphere.triangles, BuildOptions{}), "bvh/binned/bvh2", 0.0);
    const BvhView view = accel.view();
    TraversalCounters total;
    uint64_t brute_tests = 0;
    for (const Ray& ray : make_rays(sphere, 1000, 7)) {
        TraversalCounters counters;
        const Hit counted = bvh_intersect_counted(view, ray, counters);
        const Hit plain = bvh_intersect(view, ray);
        EXPECT_EQ(counted.prim, plain.prim);
        EXPECT_EQ(counted.t, plain.t);
        EXPECT_GE(counters.nodes_visited, 1u);
        EXPECT_EQ(bvh_occluded_counted(view, ray, counters), bvh_occluded(view, ray));
        total.nodes_visited += counters.nodes_visited;
        total.prims_tested += counters.prims_tested;
        brute_tests += sphere.triangles.size();
    }
    EXPECT_GT(total.prims_tested, 0u);
    // The point of a BVH: far fewer triangle tests than brute force.
    EXPECT_LT(uint64_t{total.prims_tested} * 20, brute_tests);
}

TEST(BvhTraversal, MatchesBruteForceOnStanfordBunny) {
    const std::string path = test::shared_path("scenes/stanford-bunny/bun_zipper.ply");
    if (path.empty()) GTEST_SKIP() << "shared scenes not available";
    Scene scene;
    try {
        scene = load_scene(path);
    } catch (const Error& e) {
        GTEST_SKIP() << "bunny not loadable yet: " << e.what();
    }
    const SceneGeometry g = SceneGeometry::build(scene);
    compare_with_brute_force(g, BuildOptions{}, 300, 8);
}

}  // namespace
}  // namespace rf
