// The H-PLOC builder (Benthin et al. 2024; accel/bvh/builders/hploc.cpp):
// tree quality against PLOC, LBVH and the binned SAH; the same tree for
// every thread count; degenerate inputs (1, 2, 3 triangles, one centroid,
// huge coordinates) with the tree invariants and closest hits equal to
// brute force; the radius option; emit_hploc_tree's checks. The generic
// Morton-builder checks (invariants over scenes and leaf sizes, the depth
// limit, brute-force traversal) run for Builder::Hploc in
// bvh_morton_builders_test.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/hploc.h"
#include "accel/bvh/builders/lbvh.h"
#include "accel/bvh/builders/ploc.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "bvh_invariants.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using test::check_bvh;
using test::identical;

Bvh hploc(const SceneGeometry& g, BuildOptions options = {}) {
    options.builder = Builder::Hploc;
    return build_bvh(g.triangles, options);
}

// Triangles of varying size in 50 Gaussian clusters (as in the PLOC tests).
SceneGeometry make_clustered_soup(int count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> normal(0.0f, 1.0f);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Vec3f> centres;
    for (int k = 0; k < 50; ++k) centres.push_back(test::random_in_box(rng, {Vec3f(-100.0f), Vec3f(100.0f)}));
    SceneGeometry g;
    for (int i = 0; i < count; ++i) {
        const Vec3f c = centres[static_cast<size_t>(i) % centres.size()] +
                        Vec3f(normal(rng), normal(rng), normal(rng)) * 3.0f;
        const float size = 0.05f + 0.5f * std::pow(unit(rng), 4.0f);
        test::append(g, {c + test::random_direction(rng) * size, c + test::random_direction(rng) * size,
                         c + test::random_direction(rng) * size});
    }
    g.normal_matrices.push_back(Affine3f::identity());
    return g;
}

// Closest hits (triangle and distance) and occlusion equal to brute force.
void expect_brute_force_hits(const SceneGeometry& g, const BuildOptions& options, size_t rays, uint32_t seed) {
    const auto accel = build_accel(g, options);
    const BruteForceAccel brute(g);
    size_t failures = 0;
    for (const Ray& ray : test::make_rays(g, rays, seed)) {
        const Hit expected = brute.intersect(ray), got = accel->intersect(ray);
        bool ok = got.found() == expected.found() && accel->occluded(ray) == expected.found();
        if (ok && expected.found()) {
            ok = got.t == expected.t ||
                 (got.prim != expected.prim && std::fabs(got.t - expected.t) <= 1e-5f * std::fabs(expected.t));
        }
        if (!ok && ++failures <= 3) {
            ADD_FAILURE() << "prim " << got.prim << "/" << expected.prim << " t " << got.t << "/" << expected.t;
        }
    }
    EXPECT_EQ(failures, 0u);
}

struct Costs {
    double hploc, ploc, lbvh, binned;
};

Costs sah_costs(const SceneGeometry& g) {
    const BvhBuildConfig config{};
    BuildOptions binned{.builder = Builder::BinnedSah};
    return {build_hploc(g.triangles, config, PlocOptions{}).sah_cost(),
            build_ploc(g.triangles, config, PlocOptions{}).sah_cost(),
            build_lbvh(g.triangles, config, 30).sah_cost(), build_bvh(g.triangles, binned).sah_cost()};
}

TEST(Hploc, SahCloseToPlocAndBetterThanLbvhOnClusteredScenes) {
    const SceneGeometry clustered = make_clustered_soup(40000, 12);
    const Costs c = sah_costs(clustered);
    SCOPED_TRACE("clustered: hploc " + std::to_string(c.hploc) + " ploc " + std::to_string(c.ploc) + " lbvh " +
                 std::to_string(c.lbvh) + " binned " + std::to_string(c.binned));
    EXPECT_LT(c.hploc, c.ploc * 1.03);
    EXPECT_LT(c.hploc, c.lbvh * 0.97);
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(6));
    const Costs s = sah_costs(sphere);
    SCOPED_TRACE("sphere: hploc " + std::to_string(s.hploc) + " ploc " + std::to_string(s.ploc) + " lbvh " +
                 std::to_string(s.lbvh));
    EXPECT_LT(s.hploc, s.ploc * 1.03);
    EXPECT_LT(s.hploc, s.lbvh);
}

// A uniform volumetric soup: greedy merging gains little over the Morton
// order there (see the PLOC tests); H-PLOC must stay within a few percent
// of both.
TEST(Hploc, SahCloseToPlocOnRandomSoup) {
    const SceneGeometry soup = test::make_triangle_soup(40000, 7, {Vec3f(-50.0f), Vec3f(50.0f)}, 1.0f);
    const Costs c = sah_costs(soup);
    SCOPED_TRACE("soup: hploc " + std::to_string(c.hploc) + " ploc " + std::to_string(c.ploc) + " lbvh " +
                 std::to_string(c.lbvh));
    EXPECT_LT(c.hploc, c.ploc * 1.03);
    EXPECT_LT(c.hploc, c.lbvh * 1.03);
}

TEST(Hploc, SameTreeForEveryThreadCount) {
    // Thousands of warps, so that parallel tasks race for the boundary slots.
    const SceneGeometry soup = make_clustered_soup(120000, 5);
    const Bvh one = hploc(soup, {.threads = 1});
    for (int threads : {2, 3, 0}) {
        SCOPED_TRACE(threads);
        EXPECT_TRUE(identical(one, hploc(soup, {.threads = threads})));
    }
    check_bvh(one, soup.triangles, 4);
}

TEST(Hploc, OneTwoAndThreeTriangles) {
    EXPECT_TRUE(hploc(SceneGeometry{}).nodes.empty());
    const Triangle tris[3] = {{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)},
                              {Vec3f(5, 0, 0), Vec3f(6, 0, 0), Vec3f(5, 1, 0)},
                              {Vec3f(0, 0, 9), Vec3f(1, 0, 9), Vec3f(0, 1, 9)}};
    for (size_t n = 1; n <= 3; ++n) {
        SceneGeometry g;
        for (size_t i = 0; i < n; ++i) test::append(g, tris[i]);
        for (int leaf : {1, 4}) {
            SCOPED_TRACE(std::to_string(n) + " triangles, leaves of " + std::to_string(leaf));
            const Bvh bvh = hploc(g, {.max_leaf_size = leaf});
            check_bvh(bvh, g.triangles, leaf);
            if (leaf == 1) EXPECT_EQ(bvh.nodes.size(), 2 * n - 1);
        }
    }
}

TEST(Hploc, AllCentroidsEqual) {
    // Equal codes and equal boxes (every tie), and equal codes with nested
    // boxes (tilted triangles, all boxes centred at the origin).
    SceneGeometry point, nested;
    for (int i = 0; i < 2000; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    for (int i = 1; i <= 1500; ++i) {
        const float s = 0.01f * static_cast<float>(i);
        test::append(nested, {Vec3f(-s, -s, -0.5f * s), Vec3f(s, -s, 0.5f * s), Vec3f(0, s, 0)});
    }
    for (const SceneGeometry* g : {&point, &nested}) {
        for (int leaf : {1, 4}) {
            const test::TreeShape shape = check_bvh(hploc(*g, {.max_leaf_size = leaf}), g->triangles, leaf);
            EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        }
    }
    // Identical boxes pair up (0,1), (2,3), ... as in PLOC: a balanced tree.
    const test::TreeShape shape = check_bvh(hploc(point, {.max_leaf_size = 1}), point.triangles, 1);
    EXPECT_LE(shape.max_depth, 14);
    expect_brute_force_hits(nested, {.builder = Builder::Hploc}, 500, 3);
}

TEST(Hploc, HugeCoordinatesStayFinite) {
    // Coordinates up to 1e38: extents stay finite, merged areas and SAH costs
    // overflow to infinity, and the tie rule still orders every pair. (From
    // about 1.7e38 on, box centres overflow in the shared Morton code and
    // every Morton builder's leaves come out wrong: not H-PLOC's to fix.)
    std::mt19937 rng(4);
    std::uniform_real_distribution<float> coord(-1e38f, 1e38f), small(-1.0f, 1.0f);
    SceneGeometry g;
    for (int i = 0; i < 3000; ++i) {
        const Vec3f c(coord(rng), coord(rng), coord(rng));
        if (i % 3 == 0) {
            test::append(g, {c, Vec3f(-c.x, c.y, c.z), Vec3f(c.x, -c.y, c.z)});  // spans most of the range
        } else {
            const Vec3f d(small(rng), small(rng), small(rng));
            test::append(g, {c, c + d * 1e35f, c - d * 1e35f});
        }
    }
    for (int leaf : {1, 4}) {
        const Bvh bvh = hploc(g, {.max_leaf_size = leaf});
        check_bvh(bvh, g.triangles, leaf);
        for (const BvhNode& node : bvh.nodes) {
            ASSERT_FALSE(std::isnan(node.bounds.lo.x) || std::isnan(node.bounds.hi.z));
        }
    }
    // Binary layout: the 8-wide collapse refuses the infinite SAH costs of
    // these boxes for every builder (a leaf of > 64 triangles).
    expect_brute_force_hits(g, {.builder = Builder::Hploc, .layout = Layout::Bvh2}, 800, 5);
}

TEST(Hploc, RadiusOptionIsRespected) {
    const SceneGeometry soup = make_clustered_soup(30000, 13);
    const BvhBuildConfig config{};
    const Bvh r1 = build_hploc(soup.triangles, config, {.radius = 1});
    const Bvh r8 = build_hploc(soup.triangles, config, {.radius = 8});
    const Bvh r31 = build_hploc(soup.triangles, config, {.radius = 31});
    const Bvh r256 = build_hploc(soup.triangles, config, {.radius = 256});  // clamped to 31
    check_bvh(r1, soup.triangles, 4);
    check_bvh(r31, soup.triangles, 4);
    EXPECT_FALSE(identical(r1, r8));
    EXPECT_TRUE(identical(r31, r256));
    EXPECT_LT(r8.sah_cost(), r1.sah_cost());
    const auto accel = build_accel(soup, BuildOptions{.builder = Builder::Hploc, .ploc = {.radius = 1}});
    EXPECT_NEAR(accel->stats().sah_cost, r1.sah_cost(), 1e-9 * r1.sah_cost());
}

TEST(Hploc, NameRoundTrips) {
    EXPECT_EQ(parse_builder("hploc"), Builder::Hploc);
    EXPECT_EQ(to_string(Builder::Hploc), "hploc");
}

TEST(Hploc, EmitRefusesMalformedTrees) {
    const SceneGeometry g = test::make_triangle_soup(3, 1, {Vec3f(0.0f), Vec3f(1.0f)}, 0.1f);
    const uint32_t leaf = 0x80000000u;
    const BvhBuildConfig config{};
    auto emit = [&](std::vector<uint32_t> children) {
        return emit_hploc_tree(g.triangles, config, {0, 1, 2}, children);
    };
    EXPECT_NO_THROW(emit({leaf | 0, leaf | 1, 0, leaf | 2}));
    EXPECT_THROW(emit({leaf | 0, leaf | 1}), Error);                // too few references
    EXPECT_THROW(emit({leaf | 0, leaf | 0, 0, leaf | 2}), Error);   // a leaf twice
    EXPECT_THROW(emit({leaf | 0, 1, leaf | 1, leaf | 2}), Error);   // a child numbered after its parent
    EXPECT_THROW(emit({leaf | 0, leaf | 7, 0, leaf | 2}), Error);   // no such leaf
    EXPECT_THROW(emit_hploc_tree(g.triangles, config, {0, 1}, {}), Error);
}

}  // namespace
}  // namespace rf
