// The node-pair layout of Aila and Laine 2009 ("Understanding the Efficiency
// of Ray Traversal on GPUs"): conversion invariants against the canonical
// BVH, and the shared host/device traversal against the brute-force
// reference over procedural scenes, several builders and awkward rays.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel_test_rays.h"
#include "aila_laine_test_support.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "trace/aila_laine_traversal.h"

namespace rf {
namespace {

uint32_t bits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
}

bool same_bits(const Vec3f& a, float x, float y, float z) {
    return bits(a.x) == bits(x) && bits(a.y) == bits(y) && bits(a.z) == bits(z);
}

// Random origins and directions, rays aimed at triangles, zero direction
// components and [tmin, tmax] limits (as in bvh_traversal_test.cpp).
using test::make_rays;

using test::AlwaysRefillWarp;
using test::expect_same_closest;
using test::NeverReadyWarp;
using test::RandomRefillWarp;
using test::trace_like_persistent_warp;

// Checks the converted layout against the canonical BVH it came from: the
// node pair of every canonical inner node holds its children's boxes
// (bit-exact, in the documented float4 lanes) and links of the same kind,
// every leaf's list holds exactly its references in order, with their
// vertices and indices, then a sentinel; lists tile the triangle array, every
// node is reached once, and links point forward (depth-first order).
void check_conversion(const Bvh& bvh, std::span<const Triangle> triangles, const AilaLaineBvh& al) {
    if (bvh.nodes.empty()) {
        EXPECT_EQ(al.root, kAilaLaineEntrySentinel);
        EXPECT_TRUE(al.nodes.empty());
        EXPECT_TRUE(al.triangles.empty());
        return;
    }
    size_t canonical_leaves = 0;
    for (const BvhNode& n : bvh.nodes) canonical_leaves += n.is_leaf();
    EXPECT_EQ(al.nodes.size(), bvh.nodes.size() - canonical_leaves);
    EXPECT_EQ(al.leaf_count, canonical_leaves);
    EXPECT_EQ(al.triangle_refs, bvh.prim_indices.size());
    EXPECT_EQ(al.triangles.size(), 3 * bvh.prim_indices.size() + canonical_leaves);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(al.nodes.data()) % 16, 0u);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(al.triangles.data()) % 16, 0u);

    std::vector<int> node_seen(al.nodes.size(), 0);
    std::vector<std::pair<size_t, size_t>> lists;  // [offset, end) of each leaf list
    std::vector<int> slot_seen(bvh.prim_indices.size(), 0);

    // Checks the leaf list behind `link` against canonical leaf `leaf`.
    auto check_leaf = [&](int32_t link, const BvhNode& leaf) {
        ASSERT_LT(link, 0);
        const auto offset = static_cast<size_t>(~link);
        ASSERT_LE(offset + 3 * size_t{leaf.count} + 1, al.triangles.size());
        for (uint32_t k = 0; k < leaf.count; ++k) {
            const uint32_t slot = leaf.first + k;
            ++slot_seen[slot];
            const uint32_t prim = bvh.prim_indices[slot];
            const AilaLaineFloat4* t = &al.triangles[offset + 3 * k];
            EXPECT_EQ(bits(t[0].w), prim);
            EXPECT_NE(bits(t[0].w), kAilaLaineLeafEndW);
            EXPECT_TRUE(same_bits(triangles[prim].v0, t[0].x, t[0].y, t[0].z));
            EXPECT_TRUE(same_bits(triangles[prim].v1, t[1].x, t[1].y, t[1].z));
            EXPECT_TRUE(same_bits(triangles[prim].v2, t[2].x, t[2].y, t[2].z));
        }
        const AilaLaineFloat4& end = al.triangles[offset + 3 * leaf.count];
        EXPECT_EQ(bits(end.w), kAilaLaineLeafEndW);
        EXPECT_EQ(bits(end.x), kAilaLaineLeafEndX);
        lists.emplace_back(offset, offset + 3 * leaf.count + 1);
    };

    if (bvh.nodes[0].is_leaf()) {
        ASSERT_TRUE(al.nodes.empty());
        check_leaf(al.root, bvh.nodes[0]);
    } else {
        ASSERT_EQ(al.root, 0);
        // Parallel depth-first walk: (canonical inner node, converted node).
        std::vector<std::pair<uint32_t, int32_t>> stack{{0u, 0}};
        while (!stack.empty()) {
            const auto [canonical, index] = stack.back();
            stack.pop_back();
            ASSERT_GE(index, 0);
            ASSERT_LT(static_cast<size_t>(index), al.nodes.size());
            ++node_seen[static_cast<size_t>(index)];
            const AilaLaineNode& pair = al.nodes[static_cast<size_t>(index)];
            const uint32_t left = bvh.nodes[canonical].first;
            const AilaLaineFloat4 xy[2] = {pair.xy0, pair.xy1};
            const float z_lo[2] = {pair.z.x, pair.z.z}, z_hi[2] = {pair.z.y, pair.z.w};
            for (int side = 0; side < 2; ++side) {
                const BvhNode& child = bvh.nodes[left + static_cast<uint32_t>(side)];
                EXPECT_TRUE(same_bits(child.bounds.lo, xy[side].x, xy[side].z, z_lo[side]));
                EXPECT_TRUE(same_bits(child.bounds.hi, xy[side].y, xy[side].w, z_hi[side]));
                if (child.is_leaf()) {
                    check_leaf(pair.link[side], child);
                } else {
                    EXPECT_GT(pair.link[side], index);  // depth-first: children after parents
                    stack.emplace_back(left + static_cast<uint32_t>(side), pair.link[side]);
                }
            }
            EXPECT_EQ(pair.pad[0], 0);
            EXPECT_EQ(pair.pad[1], 0);
        }
    }
    for (size_t i = 0; i < node_seen.size(); ++i) EXPECT_EQ(node_seen[i], 1) << "node " << i;
    for (size_t i = 0; i < slot_seen.size(); ++i) EXPECT_EQ(slot_seen[i], 1) << "leaf slot " << i;
    // Leaf lists are disjoint and cover the whole array.
    std::sort(lists.begin(), lists.end());
    size_t expected_offset = 0;
    for (const auto& [begin, end] : lists) {
        EXPECT_EQ(begin, expected_offset);
        expected_offset = end;
    }
    EXPECT_EQ(expected_offset, al.triangles.size());
}

void compare_with_brute_force(const SceneGeometry& g, const BuildOptions& options, size_t ray_count,
                              uint32_t seed) {
    const Bvh bvh = build_bvh(g.triangles, options);
    const AilaLaineBvh al = convert_to_aila_laine(bvh, g.triangles);
    check_conversion(bvh, g.triangles, al);
    const AilaLaineView view = al.view();
    const BruteForceAccel brute(g);
    size_t hits = 0;
    for (const Ray& ray : make_rays(g, ray_count, seed)) {
        const Hit expected = brute.intersect(ray);
        const Hit got = aila_laine_intersect(view, ray);
        expect_same_closest(got, expected, ray);
        EXPECT_EQ(aila_laine_occluded(view, ray), expected.found());
        TraversalCounters counters;
        const Hit counted = aila_laine_intersect_counted(view, ray, counters);
        EXPECT_EQ(counted.prim, got.prim);
        EXPECT_EQ(counted.t, got.t);
        EXPECT_EQ(counters.nodes_visited, 2 * counters.node_fetches);  // one fetch per node pair
        EXPECT_EQ(aila_laine_occluded_counted(view, ray, counters), expected.found());
        const Hit speculative = detail::aila_laine_traverse<false, false, NeverReadyWarp>(view, ray, nullptr);
        expect_same_closest(speculative, expected, ray);
        const bool speculative_any = detail::aila_laine_traverse<true, false, NeverReadyWarp>(view, ray, nullptr).found();
        EXPECT_EQ(speculative_any, expected.found());
        hits += expected.found();
    }
    // Stopping and resuming (dynamic fetch) must not change any result.
    const std::vector<Ray> rays = make_rays(g, ray_count, seed);
    std::vector<int> writes;
    const uint64_t yields_before = AlwaysRefillWarp::yields;
    const std::vector<Hit> closest = trace_like_persistent_warp<false, AlwaysRefillWarp>(view, rays, writes);
    EXPECT_EQ(std::count(writes.begin(), writes.end(), 1), ptrdiff_t(rays.size()));
    const std::vector<Hit> closest_random = trace_like_persistent_warp<false, RandomRefillWarp>(view, rays, writes);
    EXPECT_EQ(std::count(writes.begin(), writes.end(), 1), ptrdiff_t(rays.size()));
    const std::vector<Hit> any = trace_like_persistent_warp<true, RandomRefillWarp>(view, rays, writes);
    EXPECT_EQ(std::count(writes.begin(), writes.end(), 1), ptrdiff_t(rays.size()));
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit expected = brute.intersect(rays[i]);
        expect_same_closest(closest[i], expected, rays[i]);
        expect_same_closest(closest_random[i], expected, rays[i]);
        EXPECT_EQ(any[i].found(), expected.found());
    }
    if (!bvh.nodes.empty() && !bvh.nodes[0].is_leaf()) EXPECT_GT(AlwaysRefillWarp::yields, yields_before);
    // The rays must exercise both outcomes.
    EXPECT_GT(hits, ray_count / 5);
    EXPECT_LT(hits, ray_count);
}

constexpr Builder kBuilders[] = {Builder::BinnedSah, Builder::Sbvh, Builder::Lbvh30};

std::string name(Builder b) { return to_string(b); }

TEST(AilaLaine, MatchesBruteForceOnTriangleSoup) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    for (Builder builder : kBuilders) {
        for (int leaf : {1, 4, 8}) {
            SCOPED_TRACE(name(builder) + " leaf " + std::to_string(leaf));
            compare_with_brute_force(soup, BuildOptions{.builder = builder, .max_leaf_size = leaf}, 1000, 1);
        }
    }
}

TEST(AilaLaine, MatchesBruteForceOnTessellatedSphere) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4), 3.0f);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(sphere, BuildOptions{.builder = builder}, 2000, 2);
    }
}

TEST(AilaLaine, MatchesBruteForceOnTessellatedCube) {
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(8));
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(cube, BuildOptions{.builder = builder, .max_leaf_size = 2}, 2000, 3);
    }
}

TEST(AilaLaine, MatchesBruteForceOnDegenerateAndThinTriangles) {
    const SceneGeometry nasty = test::make_nasty_geometry(4);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(nasty, BuildOptions{.builder = builder, .max_leaf_size = 2}, 2000, 4);
    }
}

TEST(AilaLaine, MatchesBruteForceFarFromTheOrigin) {
    const SceneGeometry far = test::make_triangle_soup(2000, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    const SceneGeometry huge = test::make_triangle_soup(2000, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(far, BuildOptions{.builder = builder}, 2000, 5);
        compare_with_brute_force(huge, BuildOptions{.builder = builder}, 2000, 6);
    }
}

TEST(AilaLaine, AxisAlignedRaysAlongBoxFaces) {
    // Flat axis-aligned quads: zero direction components with origins exactly
    // on slab planes (0 * inf in the box test), one triangle per leaf.
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(6));
    const AilaLaineBvh al = convert_to_aila_laine(build_bvh(cube.triangles, BuildOptions{.max_leaf_size = 1}),
                                                  cube.triangles);
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
                expect_same_closest(aila_laine_intersect(al.view(), ray), expected, ray);
                EXPECT_EQ(aila_laine_occluded(al.view(), ray), expected.found());
                hits += expected.found();
            }
        }
    }
    EXPECT_GT(hits, 100);
}

TEST(AilaLaine, SingleTriangleIsALeafRoot) {
    SceneGeometry g;
    test::append(g, {Vec3f(-1, -1, 0), Vec3f(1, -1, 0), Vec3f(0, 1, 0)});
    const Bvh bvh = build_bvh(g.triangles, BuildOptions{});
    const AilaLaineBvh al = convert_to_aila_laine(bvh, g.triangles);
    check_conversion(bvh, g.triangles, al);
    EXPECT_TRUE(al.nodes.empty());
    EXPECT_EQ(al.root, ~0);
    EXPECT_EQ(al.triangles.size(), 4u);
    const Ray hit_ray{Vec3f(0, 0, -2), 0.0f, Vec3f(0, 0, 1)};
    const Hit hit = aila_laine_intersect(al.view(), hit_ray);
    ASSERT_TRUE(hit.found());
    EXPECT_EQ(hit.prim, 0u);
    EXPECT_EQ(hit.t, 2.0f);
    EXPECT_TRUE(aila_laine_occluded(al.view(), hit_ray));
    const Ray short_ray{Vec3f(0, 0, -2), 0.0f, Vec3f(0, 0, 1), 1.5f};
    EXPECT_FALSE(aila_laine_intersect(al.view(), short_ray).found());
    EXPECT_FALSE(aila_laine_occluded(al.view(), short_ray));
    const Ray miss_ray{Vec3f(5, 5, -2), 0.0f, Vec3f(0, 0, 1)};
    EXPECT_FALSE(aila_laine_intersect(al.view(), miss_ray).found());
    EXPECT_FALSE(aila_laine_occluded(al.view(), miss_ray));
}

TEST(AilaLaine, EmptyBvhAlwaysMisses) {
    const std::vector<Triangle> none;
    const Bvh bvh = build_bvh(none, BuildOptions{});
    const AilaLaineBvh al = convert_to_aila_laine(bvh, none);
    check_conversion(bvh, none, al);
    EXPECT_EQ(al.root, kAilaLaineEntrySentinel);
    EXPECT_EQ(al.memory_bytes(), 0u);
    const Ray ray{Vec3f(0.0f), 0.0f, Vec3f(0, 0, 1)};
    EXPECT_FALSE(aila_laine_intersect(al.view(), ray).found());
    EXPECT_FALSE(aila_laine_occluded(al.view(), ray));
    EXPECT_FALSE(aila_laine_intersect(AilaLaineView{}, ray).found());
}

// A caterpillar of `inner` inner nodes: inner node k has leaf triangle k
// (a small square-ish triangle in the plane x = k) on the left and the rest
// of the chain on the right, so a ray along -x pushes one leaf per level.
Bvh make_chain(int inner, std::vector<Triangle>& triangles) {
    triangles.clear();
    for (int k = 0; k <= inner; ++k) {
        const auto x = static_cast<float>(k);
        triangles.push_back({Vec3f(x, -1, -1), Vec3f(x, 1, -1), Vec3f(x, 0, 1)});
    }
    Bvh bvh;
    bvh.nodes.resize(2 * static_cast<size_t>(inner) + 1);
    for (int k = 0; k <= inner; ++k) bvh.prim_indices.push_back(static_cast<uint32_t>(k));
    // Inner node k at 2k, its leaf at 2k + 1, the chain's last leaf at 2 * inner.
    for (int k = inner; k >= 0; --k) {
        const size_t leaf = k == inner ? 2 * static_cast<size_t>(inner) : 2 * static_cast<size_t>(k) + 1;
        bvh.nodes[leaf] = {triangles[static_cast<size_t>(k)].bounds(), static_cast<uint32_t>(k), 1};
        if (k == inner) continue;
        BvhNode& node = bvh.nodes[2 * static_cast<size_t>(k)];
        node.first = static_cast<uint32_t>(2 * k + 1);
        node.count = 0;
        node.bounds = merge(bvh.nodes[node.first].bounds, bvh.nodes[node.first + 1].bounds);
    }
    return bvh;
}

TEST(AilaLaine, DeepestAllowedChainFillsTheStack) {
    std::vector<Triangle> triangles;
    const Bvh bvh = make_chain(kBvhMaxDepth, triangles);
    const AilaLaineBvh al = convert_to_aila_laine(bvh, triangles);
    check_conversion(bvh, triangles, al);
    ASSERT_EQ(al.nodes.size(), static_cast<size_t>(kBvhMaxDepth));
    TraversalCounters counters;
    // From beyond the far end along -x: the whole chain is descended first.
    const Ray ray{Vec3f(kBvhMaxDepth + 10.0f, 0.1f, 0.0f), 0.0f, Vec3f(-1, 0, 0)};
    const Hit hit = aila_laine_intersect_counted(al.view(), ray, counters);
    ASSERT_TRUE(hit.found());
    EXPECT_EQ(hit.prim, static_cast<uint32_t>(kBvhMaxDepth));
    EXPECT_EQ(hit.t, 10.0f);
    EXPECT_TRUE(aila_laine_occluded(al.view(), ray));
    // From the near end every leaf but the first is culled by its box.
    const Ray forward{Vec3f(-0.5f, 0.1f, 0.0f), 0.0f, Vec3f(1, 0, 0)};
    EXPECT_EQ(aila_laine_intersect(al.view(), forward).prim, 0u);

    std::vector<Triangle> deeper;
    EXPECT_THROW(convert_to_aila_laine(make_chain(kBvhMaxDepth + 1, deeper), deeper), Error);
}

TEST(AilaLaine, MalformedBvhThrows) {
    std::vector<Triangle> triangles;
    const Bvh good = make_chain(3, triangles);
    Bvh bad_child = good;
    bad_child.nodes[0].first = static_cast<uint32_t>(good.nodes.size() - 1);
    EXPECT_THROW(convert_to_aila_laine(bad_child, triangles), Error);
    Bvh cycle = good;
    cycle.nodes[2].first = 0;
    EXPECT_THROW(convert_to_aila_laine(cycle, triangles), Error);
    Bvh bad_prim = good;
    bad_prim.prim_indices[1] = 99;
    EXPECT_THROW(convert_to_aila_laine(bad_prim, triangles), Error);
    Bvh bad_range = good;
    bad_range.nodes[1].count = 50;
    EXPECT_THROW(convert_to_aila_laine(bad_range, triangles), Error);
}

}  // namespace
}  // namespace rf
