// Wide BVH layouts (BVH4, BVH8; Wald, Benthin and Boulos 2008): collapse
// invariants, and single-ray and packet traversals against the brute-force
// reference over procedural scenes, awkward rays and coherent camera rays.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/wide_bvh.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "backend/cpu/wide_bvh_packet_traversal.h"
#include "backend/cpu/wide_bvh_traversal.h"

namespace rf {
namespace {

// Random origins and directions, rays aimed at triangles, zero direction
// components and [tmin, tmax] limits (as in bvh_traversal_test.cpp).
using test::make_rays;

// Coherent rays in scanline order, as the bench makes them: a pinhole camera
// outside the scene looking at its centre, then shadow rays from the hit
// points towards a point light (so that packets are really formed).
std::vector<Ray> make_camera_rays(const SceneGeometry& g, int width, int height, Vec3f eye_dir) {
    const Vec3f centre = g.bounds.center();
    const float radius = length(g.bounds.extent()) * 0.5f;
    const Vec3f eye = centre - normalize(eye_dir) * (radius * 2.5f);
    const Vec3f forward = normalize(centre - eye);
    const Vec3f right = normalize(cross(forward, std::fabs(forward.y) < 0.9f ? Vec3f(0, 1, 0) : Vec3f(1, 0, 0)));
    const Vec3f up = cross(right, forward);
    std::vector<Ray> rays;
    for (int y = 0; y < height; ++y) {
        for (int x = 0; x < width; ++x) {
            const float px = (float(x) + 0.5f) / float(width) * 2.0f - 1.0f;
            const float py = (float(y) + 0.5f) / float(height) * 2.0f - 1.0f;
            Ray ray;
            ray.org = eye;
            ray.dir = normalize(forward + right * (px * 0.5f) + up * (py * 0.5f));
            rays.push_back(ray);
        }
    }
    return rays;
}

std::vector<Ray> make_shadow_rays(const SceneGeometry& g, const std::vector<Ray>& primary, const Accel& reference) {
    const Vec3f light = g.bounds.hi + g.bounds.extent() * 0.3f;
    std::vector<Ray> rays;
    for (const Ray& eye : primary) {
        const Hit hit = reference.intersect(eye);
        if (!hit.found()) continue;
        const Vec3f p = eye.org + eye.dir * (hit.t * 0.9999f);
        Ray ray;
        ray.org = p;
        const Vec3f to_light = light - p;
        const float distance = length(to_light);
        ray.dir = to_light * (1.0f / distance);
        ray.tmin = 0.0f;
        ray.tmax = distance;
        rays.push_back(ray);
    }
    return rays;
}

void expect_same_closest(const Hit& got, const Hit& expected, const Ray& ray, const char* what) {
    ASSERT_EQ(got.found(), expected.found()) << what;
    if (!expected.found()) return;
    if (got.prim != expected.prim) {
        // Another triangle only at (almost) the same distance: shared edges, duplicates.
        EXPECT_NEAR(got.t, expected.t, 1e-5f * std::fabs(expected.t)) << what << ": prim " << got.prim
                                                                       << " expected " << expected.prim;
    } else {
        EXPECT_EQ(got.t, expected.t) << what;
        EXPECT_EQ(got.u, expected.u) << what;
        EXPECT_EQ(got.v, expected.v) << what;
    }
    EXPECT_GE(got.t, ray.tmin) << what;
    EXPECT_LE(got.t, ray.tmax) << what;
}

// Single rays and batches (packets where the octants agree), closest and any
// hit, against brute force; returns how many rays hit.
size_t check_rays(const Accel& accel, const Accel& brute, const std::vector<Ray>& rays) {
    std::vector<Hit> batched(rays.size());
    std::vector<uint8_t> batched_occluded(rays.size(), 7);
    accel.intersect(rays, batched);
    accel.occluded(rays, batched_occluded);
    size_t hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit expected = brute.intersect(rays[i]);
        const Hit single = accel.intersect(rays[i]);
        expect_same_closest(single, expected, rays[i], "single");
        expect_same_closest(batched[i], expected, rays[i], "batched");
        expect_same_closest(batched[i], single, rays[i], "batched vs single");
        const bool occluded = accel.occluded(rays[i]);
        EXPECT_EQ(occluded, expected.found()) << "ray " << i;
        EXPECT_EQ(batched_occluded[i], occluded ? 1 : 0) << "ray " << i;
        hits += expected.found();
    }
    return hits;
}

void compare_with_brute_force(const SceneGeometry& g, BuildOptions options, size_t ray_count, uint32_t seed) {
    const BruteForceAccel brute(g);
    const std::vector<Ray> rays = make_rays(g, ray_count, seed);
    for (Layout layout : {Layout::Bvh4, Layout::Bvh8}) {
        options.layout = layout;
        SCOPED_TRACE(to_string(layout));
        const auto accel = build_accel(g, options);
        const size_t hits = check_rays(*accel, brute, rays);
        EXPECT_GT(hits, ray_count / 5);
        EXPECT_LT(hits, ray_count);
    }
}

void compare_coherent(const SceneGeometry& g, BuildOptions options, Vec3f eye_dir) {
    const BruteForceAccel brute(g);
    const std::vector<Ray> primary = make_camera_rays(g, 48, 32, eye_dir);
    const std::vector<Ray> shadow = make_shadow_rays(g, primary, brute);
    ASSERT_GT(shadow.size(), 100u);
    size_t packets = 0;
    for (size_t i = 0; i + kRayPacketSize <= primary.size(); i += kRayPacketSize)
        packets += rays_share_octant(&primary[i]) ? 1 : 0;
    EXPECT_GT(packets, primary.size() / kRayPacketSize / 2);  // packets really get used
    for (Layout layout : {Layout::Bvh4, Layout::Bvh8}) {
        options.layout = layout;
        SCOPED_TRACE(to_string(layout));
        const auto accel = build_accel(g, options);
        EXPECT_GT(check_rays(*accel, brute, primary), 100u);
        check_rays(*accel, brute, shadow);
    }
}

// Every reference the wide BVH reaches, with the boxes checked on the way.
template <int N>
void check_collapse(const SceneGeometry& g, const BuildOptions& options, bool boxes_tight) {
    const Bvh bvh = build_bvh(g.triangles, options);
    const WideBvh<N> wide = collapse_bvh<N>(bvh, g.triangles);
    std::map<uint32_t, int> expected, reached;
    for (uint32_t prim : bvh.prim_indices) ++expected[prim];
    size_t inner = 0;
    for (const BvhNode& node : bvh.nodes) inner += node.is_leaf() ? 0 : 1;
    ASSERT_GE(wide.nodes.size(), 1u);
    EXPECT_LE(wide.nodes.size(), std::max<size_t>(inner, 1));
    // Each wide node but the root replaces at least one binary inner node, and
    // N-ary nodes holding all the leaves need at least (leaves - 1) / (N - 1).
    EXPECT_GE(wide.nodes.size() * (N - 1) + 1, wide.leaf_count);

    size_t leaves = 0;
    std::vector<uint32_t> visited(wide.nodes.size(), 0);
    std::vector<uint32_t> stack{0};
    while (!stack.empty()) {
        const uint32_t index = stack.back();
        stack.pop_back();
        ++visited[index];
        const WideNode<N>& node = wide.nodes[index];
        int used = 0;
        for (int c = 0; c < N; ++c) {
            const uint32_t ref = node.child[c];
            if (ref == kWideEmptyRef) {
                // Empty slots come last and can never be entered.
                for (int k = c; k < N; ++k) {
                    EXPECT_EQ(node.child[k], kWideEmptyRef);
                    EXPECT_GT(node.bounds[0][k], node.bounds[1][k]);
                }
                break;
            }
            ++used;
            Box3f slot;
            slot.lo = Vec3f(node.bounds[0][c], node.bounds[2][c], node.bounds[4][c]);
            slot.hi = Vec3f(node.bounds[1][c], node.bounds[3][c], node.bounds[5][c]);
            if (wide_is_leaf(ref)) {
                ++leaves;
                const uint32_t first = wide_leaf_first_pack(ref);
                for (uint32_t p = first; p < first + wide_leaf_pack_count(ref); ++p) {
                    ASSERT_LT(p, wide.packs.size());
                    int filled = 0;
                    for (uint32_t prim : wide.packs[p].prim) {
                        if (prim == kInvalidId) continue;
                        ++filled;
                        ++reached[prim];
                        if (boxes_tight) EXPECT_TRUE(slot.contains(g.triangles[prim].bounds()));
                    }
                    EXPECT_GT(filled, 0);  // no empty packs
                }
            } else {
                ASSERT_LT(ref, wide.nodes.size());
                const WideNode<N>& child = wide.nodes[ref];
                for (int k = 0; k < N && child.child[k] != kWideEmptyRef; ++k) {
                    Box3f inner_box;
                    inner_box.lo = Vec3f(child.bounds[0][k], child.bounds[2][k], child.bounds[4][k]);
                    inner_box.hi = Vec3f(child.bounds[1][k], child.bounds[3][k], child.bounds[5][k]);
                    EXPECT_TRUE(slot.contains(inner_box));
                }
                stack.push_back(ref);
            }
        }
        EXPECT_GE(used, index == 0 ? 1 : 2);  // only a tiny root holds a single leaf
    }
    EXPECT_EQ(leaves, wide.leaf_count);
    EXPECT_EQ(reached, expected);
    for (uint32_t count : visited) EXPECT_EQ(count, 1u);  // a tree: every node reached once
}

TEST(WideBvhCollapse, ReferencesAndBoxesAreKept) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 31, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(3));
    const SceneGeometry nasty = test::make_nasty_geometry(5);
    for (int leaf : {1, 4, 8, 64}) {
        check_collapse<4>(soup, BuildOptions{.max_leaf_size = leaf}, true);
        check_collapse<8>(soup, BuildOptions{.max_leaf_size = leaf}, true);
    }
    check_collapse<4>(sphere, BuildOptions{}, true);
    check_collapse<8>(sphere, BuildOptions{}, true);
    check_collapse<4>(nasty, BuildOptions{.max_leaf_size = 2}, true);
    check_collapse<8>(nasty, BuildOptions{.max_leaf_size = 2}, true);
    // SBVH references a triangle from several leaves, each with a clipped box.
    check_collapse<4>(soup, BuildOptions{.builder = Builder::Sbvh}, false);
    check_collapse<8>(soup, BuildOptions{.builder = Builder::Sbvh}, false);
}

TEST(WideBvhCollapse, TinyAndEmptyScenes) {
    const SceneGeometry one = test::make_triangle_soup(1, 3, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.5f);
    check_collapse<8>(one, BuildOptions{}, true);
    const SceneGeometry three = test::make_triangle_soup(3, 3, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.5f);
    check_collapse<4>(three, BuildOptions{}, true);
    const SceneGeometry empty;
    for (Layout layout : {Layout::Bvh4, Layout::Bvh8}) {
        const auto accel = build_accel(empty, BuildOptions{.layout = layout});
        const Ray ray{Vec3f(0.0f), 0.0f, Vec3f(0, 0, 1)};
        EXPECT_FALSE(accel->intersect(ray).found());
        EXPECT_FALSE(accel->occluded(ray));
        std::vector<Ray> rays(20, ray);
        std::vector<Hit> hits(rays.size());
        std::vector<uint8_t> occluded(rays.size(), 1);
        accel->intersect(rays, hits);
        accel->occluded(rays, occluded);
        for (size_t i = 0; i < rays.size(); ++i) {
            EXPECT_FALSE(hits[i].found());
            EXPECT_EQ(occluded[i], 0);
        }
        EXPECT_EQ(accel->stats().node_count, 0u);
    }
    const BruteForceAccel brute(one);
    const auto accel = build_accel(one, BuildOptions{.layout = Layout::Bvh8});
    check_rays(*accel, brute, make_rays(one, 200, 9));
}

TEST(WideBvhTraversal, MatchesBruteForceOnTriangleSoup) {
    const SceneGeometry soup = test::make_triangle_soup(4000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    for (int leaf : {1, 4, 8}) compare_with_brute_force(soup, BuildOptions{.max_leaf_size = leaf}, 1200, 1);
    compare_with_brute_force(soup, BuildOptions{.builder = Builder::Sbvh}, 1200, 11);
}

TEST(WideBvhTraversal, MatchesBruteForceOnTessellatedSphereAndCube) {
    compare_with_brute_force(test::to_geometry(test::make_icosphere(4), 3.0f), BuildOptions{}, 2500, 2);
    compare_with_brute_force(test::to_geometry(test::make_tessellated_cube(12)), BuildOptions{}, 2500, 12);
}

TEST(WideBvhTraversal, MatchesBruteForceOnDegenerateAndThinTriangles) {
    compare_with_brute_force(test::make_nasty_geometry(4), BuildOptions{.max_leaf_size = 2}, 2500, 3);
}

TEST(WideBvhTraversal, MatchesBruteForceFarFromTheOrigin) {
    const SceneGeometry far = test::make_triangle_soup(2000, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    compare_with_brute_force(far, BuildOptions{}, 2500, 4);
    const SceneGeometry huge = test::make_triangle_soup(2000, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f);
    compare_with_brute_force(huge, BuildOptions{}, 2500, 5);
}

TEST(WideBvhTraversal, AxisAlignedRaysAlongBoxFaces) {
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(6));
    const BruteForceAccel brute(cube);
    std::vector<Ray> rays;
    for (int i = -6; i <= 6; ++i) {
        for (int j = -6; j <= 6; ++j) {
            const float a = static_cast<float>(i) / 3.0f, b = static_cast<float>(j) / 3.0f;
            for (const Ray& ray : {Ray{Vec3f(a, b, -5.0f), 0.0f, Vec3f(0, 0, 1)},
                                   Ray{Vec3f(5.0f, a, b), 0.0f, Vec3f(-1, 0, 0)},
                                   Ray{Vec3f(a, -5.0f, b), 0.0f, Vec3f(0, 2, 0)},
                                   Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(0, 0, -1)}}) {
                rays.push_back(ray);
            }
        }
    }
    for (Layout layout : {Layout::Bvh4, Layout::Bvh8}) {
        const auto accel = build_accel(cube, BuildOptions{.layout = layout, .max_leaf_size = 1});
        EXPECT_GT(check_rays(*accel, brute, rays), 100u);
    }
}

// The one-FMA slab test replaces tiny direction components by a small signed
// value; rays with such components (down to denormals), near the origin and
// far from it, must still find what brute force finds.
TEST(WideBvhTraversal, TinyDirectionComponents) {
    const float tiny_values[] = {1e-42f, -1e-38f, 1e-30f, -1e-20f, 1e-12f, -1e-7f};
    for (const SceneGeometry& g : {test::to_geometry(test::make_tessellated_cube(8)),
                                   test::make_triangle_soup(1500, 27, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f)}) {
        const BruteForceAccel brute(g);
        std::vector<Ray> rays = make_rays(g, 1500, 13);
        std::mt19937 rng(14);
        for (size_t i = 0; i < rays.size(); ++i) {
            Ray& ray = rays[i];
            ray.dir[int(i % 3)] = tiny_values[i % 6];
            if (i % 4 == 0) ray.dir[int((i + 1) % 3)] = tiny_values[(i / 6) % 6];
            if (length_squared(ray.dir) < 1e-20f) ray.dir[int((i + 2) % 3)] = 1.0f;
        }
        for (Layout layout : {Layout::Bvh4, Layout::Bvh8}) {
            const auto accel = build_accel(g, BuildOptions{.layout = layout});
            EXPECT_GT(check_rays(*accel, brute, rays), 20u);
        }
    }
}

TEST(WideBvhTraversal, CoherentPacketsMatchBruteForce) {
    compare_coherent(test::to_geometry(test::make_icosphere(4), 3.0f), BuildOptions{}, Vec3f(0.3f, -0.2f, 1.0f));
    compare_coherent(test::to_geometry(test::make_tessellated_cube(10)), BuildOptions{}, Vec3f(-1.0f, -0.7f, -0.4f));
    compare_coherent(test::make_triangle_soup(4000, 25, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f), BuildOptions{},
                     Vec3f(0.5f, 0.5f, -1.0f));
    compare_coherent(test::make_triangle_soup(2000, 26, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f), BuildOptions{},
                     Vec3f(1.0f, 0.2f, 0.1f));
}

TEST(WideBvhTraversal, StatsAndCounters) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    const Bvh bvh = build_bvh(sphere.triangles, BuildOptions{});
    const std::vector<Ray> rays = make_rays(sphere, 500, 7);
    for (Layout layout : {Layout::Bvh4, Layout::Bvh8}) {
        const auto accel = build_accel(sphere, BuildOptions{.layout = layout});
        const AccelStats s = accel->stats();
        EXPECT_EQ(s.name, "bvh/binned/" + to_string(layout));
        EXPECT_GT(s.node_count, 0u);
        EXPECT_GT(s.leaf_count, 0u);
        EXPECT_GT(s.bytes, 0u);
        EXPECT_GE(s.layout_ms, 0.0);
        EXPECT_GE(s.build_ms, s.layout_ms);
        EXPECT_NEAR(s.sah_cost, bvh.sah_cost(), 1e-6 * bvh.sah_cost());  // of the source BVH2
        EXPECT_NEAR(s.quality_cost, bvh.quality_cost(), 1e-6 * bvh.quality_cost());
        TraversalTotals totals;
        EXPECT_TRUE(accel->count_traversal(rays, false, totals));
        EXPECT_EQ(totals.rays, rays.size());
        EXPECT_GE(totals.steps, rays.size());
        EXPECT_GT(totals.prim_tests, 0u);
        EXPECT_LT(totals.prim_tests * 20, uint64_t(rays.size()) * sphere.triangles.size());
        TraversalTotals any;
        EXPECT_TRUE(accel->count_traversal(rays, true, any));
        EXPECT_LE(any.prim_tests, totals.prim_tests);
    }
}

}  // namespace
}  // namespace rf
