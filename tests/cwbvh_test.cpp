// The compressed 8-wide BVH of Ylitie, Karras and Laine 2017 ("Efficient
// Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs"): the
// 80-byte node, conservative 8-bit quantisation, the layout invariants of a
// real build (contiguous children and triangles, leaves of at most three
// triangles, every reference stored once, octant slot order assigned
// optimally by the auction algorithm), and the shared host/device traversal,
// with and without the postponing of triangle groups, against the
// brute-force reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "math/random.h"
#include "trace/bvh_traversal.h"
#include "trace/cwbvh_traversal.h"

namespace rf {
namespace {

uint32_t bits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
}

bool same_bits(const Vec3f& a, const CwbvhFloat4& b) {
    return bits(a.x) == bits(b.x) && bits(a.y) == bits(b.y) && bits(a.z) == bits(b.z);
}

void expect_same_closest(const Hit& got, const Hit& brute, const Ray& ray) {
    ASSERT_EQ(got.found(), brute.found());
    if (!brute.found()) return;
    if (got.prim != brute.prim) {
        // Another triangle at (almost) the same distance: shared edges, duplicates.
        EXPECT_NEAR(got.t, brute.t, 1e-5f * std::fabs(brute.t)) << "prim " << got.prim << " brute " << brute.prim;
    } else {
        EXPECT_EQ(got.t, brute.t);
        EXPECT_EQ(got.u, brute.u);
        EXPECT_EQ(got.v, brute.v);
    }
    EXPECT_GE(got.t, ray.tmin);
    EXPECT_LE(got.t, ray.tmax);
}

// Walks the layout from the root and checks every invariant of the format
// against the canonical BVH it came from. `exact_references`: each
// triangle's box lies in every box above it (no spatial splits), so every
// dequantised slot box must contain the boxes of all triangles below it.
void check_layout(const Bvh& bvh, const std::vector<Triangle>& triangles, const CwbvhBvh& cw,
                  bool exact_references) {
    if (bvh.nodes.empty()) {
        EXPECT_TRUE(cw.nodes.empty());
        EXPECT_TRUE(cw.triangles.empty());
        EXPECT_EQ(cw.memory_bytes(), 0u);
        return;
    }
    ASSERT_FALSE(cw.nodes.empty());
    EXPECT_EQ(reinterpret_cast<uintptr_t>(cw.nodes.data()) % 16, 0u);
    EXPECT_EQ(cw.memory_bytes(), cw.nodes.size() * 80 + cw.triangles.size() * 48);
    std::vector<int> node_seen(cw.nodes.size(), 0);
    std::vector<int> triangle_seen(cw.triangles.size(), 0);
    size_t leaves = 0;
    int max_depth = 0;

    struct Item {
        uint32_t node;
        int depth;
    };
    // Depth-first from the root; `order` keeps the pre-order for the
    // bottom-up box check below.
    std::vector<Box3f> subtree_box(cw.nodes.size());
    std::vector<uint32_t> order;  // nodes in pre-order
    std::vector<Item> stack{{0u, 1}};
    node_seen[0] = 1;
    while (!stack.empty()) {
        const Item item = stack.back();
        stack.pop_back();
        order.push_back(item.node);
        max_depth = std::max(max_depth, item.depth);
        const CwbvhNode& n = cw.nodes[item.node];
        uint32_t rank = 0;
        int offset = 0;
        for (int s = 0; s < kCwbvhWidth; ++s) {
            const uint8_t meta = n.meta[s];
            const bool inner_bit = (n.imask >> s) & 1u;
            if (meta == kCwbvhEmptyMeta) {
                EXPECT_FALSE(inner_bit);
                EXPECT_EQ(n.q_lo_x[s] | n.q_lo_y[s] | n.q_lo_z[s] | n.q_hi_x[s] | n.q_hi_y[s] | n.q_hi_z[s], 0);
                continue;
            }
            EXPECT_LE(n.q_lo_x[s], n.q_hi_x[s]);
            EXPECT_LE(n.q_lo_y[s], n.q_hi_y[s]);
            EXPECT_LE(n.q_lo_z[s], n.q_hi_z[s]);
            ASSERT_EQ(cwbvh_meta_is_inner(meta), inner_bit) << "slot " << s;
            if (inner_bit) {
                EXPECT_EQ(meta, cwbvh_inner_meta(s));
                const uint32_t child = n.base_index_child + rank++;
                ASSERT_LT(child, cw.nodes.size());
                EXPECT_GT(child, item.node);
                ASSERT_EQ(node_seen[child]++, 0) << "node " << child << " reached twice";
                stack.push_back({child, item.depth + 1});
            } else {
                const int count = std::popcount(unsigned(meta >> 5));
                ASSERT_GE(count, 1);
                ASSERT_LE(count, kCwbvhMaxLeafTriangles);
                EXPECT_EQ(meta >> 5, (1 << count) - 1) << "unary count";
                EXPECT_EQ(meta & 31, offset) << "leaf triangles contiguous in slot order";
                for (int k = 0; k < count; ++k) {
                    const size_t t = size_t{n.base_index_triangle} + size_t(offset + k);
                    ASSERT_LT(t, cw.triangles.size());
                    ++triangle_seen[t];
                }
                offset += count;
                ++leaves;
            }
        }
        EXPECT_LE(offset, 24);
    }
    for (size_t i = 0; i < node_seen.size(); ++i) EXPECT_EQ(node_seen[i], 1) << "node " << i;
    for (size_t i = 0; i < triangle_seen.size(); ++i) EXPECT_EQ(triangle_seen[i], 1) << "triangle " << i;
    EXPECT_EQ(cw.leaf_count, leaves);
    EXPECT_EQ(cw.depth, max_depth);
    EXPECT_LE(cw.depth, kCwbvhMaxDepth);

    // Stored triangles: original vertices, bit for bit, and exactly the
    // canonical references (each triangle once without spatial splits).
    std::vector<uint32_t> stored;
    for (const CwbvhTriangle& t : cw.triangles) {
        const uint32_t prim = bits(t.v0.w);
        ASSERT_LT(prim, triangles.size());
        EXPECT_TRUE(same_bits(triangles[prim].v0, t.v0));
        EXPECT_TRUE(same_bits(triangles[prim].v1, t.v1));
        EXPECT_TRUE(same_bits(triangles[prim].v2, t.v2));
        stored.push_back(prim);
    }
    std::vector<uint32_t> canonical = bvh.prim_indices;
    std::sort(stored.begin(), stored.end());
    std::sort(canonical.begin(), canonical.end());
    EXPECT_EQ(stored, canonical);

    if (!exact_references) return;
    // Bottom-up (reverse pre-order): every slot's dequantised box contains
    // the exact bounds of everything below it.
    for (size_t i = order.size(); i-- > 0;) {
        const CwbvhNode& n = cw.nodes[order[i]];
        Box3f node_box;
        uint32_t rank = 0;
        for (int s = 0; s < kCwbvhWidth; ++s) {
            if (n.meta[s] == kCwbvhEmptyMeta) continue;
            Box3f exact;
            if (cwbvh_meta_is_inner(n.meta[s])) {
                exact = subtree_box[n.base_index_child + rank++];
            } else {
                const int count = std::popcount(unsigned(n.meta[s] >> 5));
                for (int k = 0; k < count; ++k) {
                    const CwbvhTriangle& t = cw.triangles[n.base_index_triangle + uint32_t((n.meta[s] & 31) + k)];
                    exact.extend(triangles[bits(t.v0.w)].bounds());
                }
            }
            const Box3f q = cwbvh_child_box(n, s);
            EXPECT_TRUE(q.contains(exact)) << "node " << order[i] << " slot " << s;
            node_box.extend(exact);
        }
        subtree_box[order[i]] = node_box;
    }
}

// Postponement policies for the host (the default never postpones there).
// Both record how often they were asked and the deepest stack they saw.
struct PostponeCount {
    size_t asked = 0;
    size_t postponed = 0;
    int max_stack = 0;
    void begin_iteration() {}
    void pushed(int size) { max_stack = std::max(max_stack, size); }
};
struct AlwaysPostpone : PostponeCount {
    bool postpone() {
        ++asked;
        ++postponed;
        return true;
    }
};
// Postpones when a hash of (seed, step) is odd: about half the time, with no
// pattern tied to the tree.
struct RandomPostpone : PostponeCount {
    uint32_t seed = 0;
    uint32_t step = 0;
    bool postpone() {
        ++asked;
        const bool yes = (pcg_hash(seed ^ pcg_hash(step++)) & 1u) != 0;
        postponed += yes;
        return yes;
    }
};

bool same_counters(const CwbvhCounters& a, const CwbvhCounters& b) {
    return a.nodes_visited == b.nodes_visited && a.boxes_tested == b.boxes_tested && a.prims_tested == b.prims_tested;
}

// Closest and any hit with both test policies against brute force. On a
// ray that hits nothing tmax never shrinks, so postponing must not change
// which nodes, boxes and triangles are tested, only their order.
void compare_postponing_with_brute_force(const CwbvhView& view, const Ray& ray, const Hit& expected,
                                         AlwaysPostpone& always, RandomPostpone& random) {
    CwbvhCounters plain, with_always, with_random;
    cwbvh_intersect_counted(view, ray, plain);
    expect_same_closest(cwbvh_intersect_counted(view, ray, with_always, always), expected, ray);
    expect_same_closest(cwbvh_intersect_counted(view, ray, with_random, random), expected, ray);
    EXPECT_EQ(cwbvh_occluded(view, ray, always), expected.found());
    EXPECT_EQ(cwbvh_occluded(view, ray, random), expected.found());
    if (!expected.found()) {
        EXPECT_TRUE(same_counters(plain, with_always));
        EXPECT_TRUE(same_counters(plain, with_random));
    }
}

void compare_with_brute_force(const SceneGeometry& g, const BuildOptions& options, size_t ray_count,
                              uint32_t seed) {
    const Bvh bvh = build_bvh(g.triangles, options);
    const CwbvhBvh cw = build_cwbvh(bvh, g.triangles);
    check_layout(bvh, g.triangles, cw, options.builder != Builder::Sbvh);
    const CwbvhView view = cw.view();
    const BruteForceAccel brute(g);
    size_t hits = 0;
    AlwaysPostpone always;
    RandomPostpone random;
    random.seed = seed;
    for (const Ray& ray : test::make_rays(g, ray_count, seed)) {
        const Hit expected = brute.intersect(ray);
        const Hit got = cwbvh_intersect(view, ray);
        expect_same_closest(got, expected, ray);
        EXPECT_EQ(cwbvh_occluded(view, ray), expected.found());
        TraversalCounters counters;
        const Hit counted = cwbvh_intersect_counted(view, ray, counters);
        EXPECT_EQ(counted.prim, got.prim);
        EXPECT_EQ(counted.t, got.t);
        EXPECT_EQ(cwbvh_occluded_counted(view, ray, counters), expected.found());
        CwbvhCounters all;
        EXPECT_EQ(cwbvh_intersect_counted(view, ray, all).prim, got.prim);
        compare_postponing_with_brute_force(view, ray, expected, always, random);
        hits += expected.found();
    }
    // The rays must exercise both outcomes.
    EXPECT_GT(hits, ray_count / 5);
    EXPECT_LT(hits, ray_count);
    // Where a node has both leaves and inner children (not so in every
    // regular tessellation), the policies were consulted: postponing
    // happened, at random about half the time. The stack stayed within its
    // bound: one node group and one triangle group per level below the root.
    const bool mixed_node = std::any_of(cw.nodes.begin(), cw.nodes.end(), [](const CwbvhNode& n) {
        return n.imask != 0 && std::any_of(n.meta, n.meta + kCwbvhWidth, [](uint8_t m) {
                   return m != kCwbvhEmptyMeta && !cwbvh_meta_is_inner(m);
               });
    });
    if (mixed_node) {
        EXPECT_GT(always.postponed, 0u);
        EXPECT_GT(random.postponed, 0u);
        EXPECT_LT(random.postponed, random.asked);
    }
    for (const PostponeCount* policy : {static_cast<const PostponeCount*>(&always), static_cast<const PostponeCount*>(&random)}) {
        EXPECT_LE(policy->max_stack, 2 * (cw.depth - 1));
        EXPECT_LE(policy->max_stack, kCwbvhTraversalStackSize);
    }
}

constexpr Builder kBuilders[] = {Builder::BinnedSah, Builder::Sbvh, Builder::Lbvh30};

std::string name(Builder b) { return to_string(b); }

TEST(Cwbvh, NodeIsTheEightyBytePaperLayout) {
    static_assert(sizeof(CwbvhNode) == 80);
    EXPECT_EQ(alignof(CwbvhNode), 16u);
    EXPECT_EQ(offsetof(CwbvhNode, p), 0u);
    EXPECT_EQ(offsetof(CwbvhNode, e), 12u);
    EXPECT_EQ(offsetof(CwbvhNode, imask), 15u);
    EXPECT_EQ(offsetof(CwbvhNode, base_index_child), 16u);
    EXPECT_EQ(offsetof(CwbvhNode, base_index_triangle), 20u);
    EXPECT_EQ(offsetof(CwbvhNode, meta), 24u);
    EXPECT_EQ(offsetof(CwbvhNode, q_lo_x), 32u);
    EXPECT_EQ(offsetof(CwbvhNode, q_hi_z), 72u);
    EXPECT_EQ(sizeof(CwbvhTriangle), 48u);
    // The meta encodings of the paper.
    EXPECT_EQ(cwbvh_inner_meta(0), 0b00111000);
    EXPECT_EQ(cwbvh_inner_meta(7), 0b00111111);
    EXPECT_EQ(cwbvh_leaf_meta(1, 0), 0b00100000);
    EXPECT_EQ(cwbvh_leaf_meta(2, 5), 0b01100101);
    EXPECT_EQ(cwbvh_leaf_meta(3, 21), 0b11110101);
    for (int offset = 0; offset + 1 <= 24; ++offset) {
        for (int count = 1; count <= 3 && offset + count <= 24; ++count) {
            EXPECT_FALSE(cwbvh_meta_is_inner(cwbvh_leaf_meta(count, offset)));
        }
    }
    for (int s = 0; s < 8; ++s) EXPECT_TRUE(cwbvh_meta_is_inner(cwbvh_inner_meta(s)));
}

// Random child boxes at many scales and offsets, flat and tiny ones
// included: the dequantised boxes contain them and are not much larger.
TEST(Cwbvh, QuantisedBoxesContainTheExactOnes) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const float offsets[] = {0.0f, -3.0f, 1e6f, -1e6f, 1e-20f, 7e30f};
    const float sizes[] = {1e-30f, 1e-6f, 1.0f, 1e3f, 1e6f, 1e30f};
    int checked = 0;
    for (float offset : offsets) {
        for (float size : sizes) {
            for (int trial = 0; trial < 40; ++trial) {
                Box3f boxes[kCwbvhWidth];
                const unsigned used = 1u + unsigned(rng() % 255u);
                for (int s = 0; s < kCwbvhWidth; ++s) {
                    for (int a = 0; a < 3; ++a) {
                        float x = offset + size * unit(rng), y = offset + size * unit(rng);
                        if (trial % 5 == 0) y = x;  // flat
                        boxes[s].lo[a] = std::min(x, y);
                        boxes[s].hi[a] = std::max(x, y);
                    }
                }
                CwbvhNode node{};
                ASSERT_TRUE(cwbvh_quantize(node, boxes, used));
                Box3f all;
                for (int s = 0; s < kCwbvhWidth; ++s) {
                    if ((used >> s) & 1u) all.extend(boxes[s]);
                }
                for (int a = 0; a < 3; ++a) {
                    EXPECT_EQ(node.p[a], all.lo[a]);
                    const float step = cwbvh_step(node.e[a]);
                    // The smallest power-of-two step, unless rounding near p
                    // forced one more doubling (at most one, p's ulp permitting).
                    const double extent = double(all.hi[a]) - double(all.lo[a]);
                    const double spacing = double(std::nextafter(std::fabs(all.hi[a]), INFINITY) - std::fabs(all.hi[a]));
                    if (node.e[a] > 1) {
                        EXPECT_LT(double(step) * 255.0, 2.0 * extent + 512.0 * spacing);
                    }
                }
                for (int s = 0; s < kCwbvhWidth; ++s) {
                    if (!((used >> s) & 1u)) continue;
                    const Box3f q = cwbvh_child_box(node, s);
                    EXPECT_TRUE(q.contains(boxes[s])) << "offset " << offset << " size " << size;
                    for (int a = 0; a < 3; ++a) {
                        // At most one grid step of slack per side beyond rounding.
                        const float step = cwbvh_step(node.e[a]);
                        const uint8_t* lo = a == 0 ? node.q_lo_x : a == 1 ? node.q_lo_y : node.q_lo_z;
                        const uint8_t* hi = a == 0 ? node.q_hi_x : a == 1 ? node.q_hi_y : node.q_hi_z;
                        const double cells = (double(boxes[s].hi[a]) - double(boxes[s].lo[a])) / double(step);
                        EXPECT_LE(double(hi[s] - lo[s]), std::ceil(cells) + 2.0 +
                                                              2.0 * double(std::fabs(node.p[a])) * 0x1p-23 / double(step));
                    }
                    ++checked;
                }
            }
        }
    }
    EXPECT_GT(checked, 5000);
    // Unused slots are zero; extents near FLT_MAX cannot be quantised.
    Box3f boxes[kCwbvhWidth];
    boxes[0] = {Vec3f(-3e38f), Vec3f(3e38f)};
    CwbvhNode node{};
    EXPECT_FALSE(cwbvh_quantize(node, boxes, 1u));
    boxes[0] = {Vec3f(0.0f), Vec3f(INFINITY)};
    EXPECT_FALSE(cwbvh_quantize(node, boxes, 1u));
}

TEST(Cwbvh, MatchesBruteForceOnTriangleSoup) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    for (Builder builder : kBuilders) {
        for (int leaf : {1, 4, 8}) {
            SCOPED_TRACE(name(builder) + " leaf " + std::to_string(leaf));
            compare_with_brute_force(soup, BuildOptions{.builder = builder, .max_leaf_size = leaf}, 800, 1);
        }
    }
}

TEST(Cwbvh, LargeCanonicalLeavesAreSplitIntoLeavesOfAtMostThree) {
    const SceneGeometry soup = test::make_triangle_soup(2000, 31, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.5f);
    // Leaves of up to 64 references, built with a high traversal cost so that they fill up.
    const BuildOptions options{.max_leaf_size = 64, .sah = {.traversal = 50.0f}};
    const Bvh bvh = build_bvh(soup.triangles, options);
    size_t largest = 0;
    for (const BvhNode& n : bvh.nodes) largest = std::max<size_t>(largest, n.count);
    EXPECT_GT(largest, 8u);
    compare_with_brute_force(soup, options, 1000, 11);
}

TEST(Cwbvh, MatchesBruteForceOnTessellatedSphere) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4), 3.0f);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(sphere, BuildOptions{.builder = builder}, 1500, 2);
    }
}

TEST(Cwbvh, MatchesBruteForceOnTessellatedCube) {
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(8));
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(cube, BuildOptions{.builder = builder, .max_leaf_size = 2}, 2000, 3);
    }
}

TEST(Cwbvh, MatchesBruteForceOnDegenerateAndThinTriangles) {
    const SceneGeometry nasty = test::make_nasty_geometry(4);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(nasty, BuildOptions{.builder = builder, .max_leaf_size = 2}, 2000, 4);
    }
}

TEST(Cwbvh, MatchesBruteForceOnManyCoincidentTriangles) {
    // 400 copies of one triangle, 100 copies of one zero-area point, and a
    // few other triangles: every box ties, the DP must still stay shallow.
    SceneGeometry g;
    for (int i = 0; i < 400; ++i) test::append(g, {Vec3f(-1, -1, 0), Vec3f(1, -1, 0), Vec3f(0, 1, 0)});
    for (int i = 0; i < 100; ++i) test::append(g, {Vec3f(0.5f), Vec3f(0.5f), Vec3f(0.5f)});
    for (int i = 0; i < 20; ++i) {
        const float z = float(i) * 0.25f + 0.1f;
        test::append(g, {Vec3f(-2, -2, z), Vec3f(2, -2, z), Vec3f(0, 2, z)});
    }
    g.normal_matrices.push_back(Affine3f::identity());
    for (Builder builder : kBuilders) {
        for (int leaf : {1, 8}) {
            SCOPED_TRACE(name(builder) + " leaf " + std::to_string(leaf));
            compare_with_brute_force(g, BuildOptions{.builder = builder, .max_leaf_size = leaf}, 1000, 12);
        }
    }
}

TEST(Cwbvh, MatchesBruteForceFarFromTheOrigin) {
    const SceneGeometry far = test::make_triangle_soup(2000, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    const SceneGeometry huge = test::make_triangle_soup(2000, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(name(builder));
        compare_with_brute_force(far, BuildOptions{.builder = builder}, 1500, 5);
        compare_with_brute_force(huge, BuildOptions{.builder = builder}, 1500, 6);
    }
}

TEST(Cwbvh, AxisAlignedRaysAlongBoxFaces) {
    // Flat axis-aligned quads: zero direction components with origins exactly
    // on slab planes (0 * inf in the box test).
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(6));
    const Bvh bvh = build_bvh(cube.triangles, BuildOptions{.max_leaf_size = 1});
    const CwbvhBvh cw = build_cwbvh(bvh, cube.triangles);
    check_layout(bvh, cube.triangles, cw, true);
    const BruteForceAccel brute(cube);
    int hits = 0;
    for (int i = -6; i <= 6; ++i) {
        for (int j = -6; j <= 6; ++j) {
            const float a = static_cast<float>(i) / 3.0f, b = static_cast<float>(j) / 3.0f;
            for (const Ray& ray : {Ray{Vec3f(a, b, -5.0f), 0.0f, Vec3f(0, 0, 1)},
                                   Ray{Vec3f(5.0f, a, b), 0.0f, Vec3f(-1, 0, 0)},
                                   Ray{Vec3f(a, -5.0f, b), 0.0f, Vec3f(0, 2, 0)},
                                   Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(0, 0, -1)},
                                   Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(-0.0f, 0.0f, 1)}}) {
                const Hit expected = brute.intersect(ray);
                expect_same_closest(cwbvh_intersect(cw.view(), ray), expected, ray);
                EXPECT_EQ(cwbvh_occluded(cw.view(), ray), expected.found());
                hits += expected.found();
            }
        }
    }
    EXPECT_GT(hits, 100);
}

TEST(Cwbvh, SingleTriangleIsAOneSlotRoot) {
    SceneGeometry g;
    test::append(g, {Vec3f(-1, -1, 0), Vec3f(1, -1, 0), Vec3f(0, 1, 0)});
    const Bvh bvh = build_bvh(g.triangles, BuildOptions{});
    const CwbvhBvh cw = build_cwbvh(bvh, g.triangles);
    check_layout(bvh, g.triangles, cw, true);
    ASSERT_EQ(cw.nodes.size(), 1u);
    ASSERT_EQ(cw.triangles.size(), 1u);
    EXPECT_EQ(cw.nodes[0].imask, 0);
    const Ray hit_ray{Vec3f(0, 0, -2), 0.0f, Vec3f(0, 0, 1)};
    const Hit hit = cwbvh_intersect(cw.view(), hit_ray);
    ASSERT_TRUE(hit.found());
    EXPECT_EQ(hit.prim, 0u);
    EXPECT_EQ(hit.t, 2.0f);
    EXPECT_TRUE(cwbvh_occluded(cw.view(), hit_ray));
    const Ray short_ray{Vec3f(0, 0, -2), 0.0f, Vec3f(0, 0, 1), 1.5f};
    EXPECT_FALSE(cwbvh_intersect(cw.view(), short_ray).found());
    EXPECT_FALSE(cwbvh_occluded(cw.view(), short_ray));
    const Ray miss_ray{Vec3f(5, 5, -2), 0.0f, Vec3f(0, 0, 1)};
    EXPECT_FALSE(cwbvh_intersect(cw.view(), miss_ray).found());
    EXPECT_FALSE(cwbvh_occluded(cw.view(), miss_ray));
}

TEST(Cwbvh, EmptySceneAlwaysMisses) {
    const std::vector<Triangle> none;
    const Bvh bvh = build_bvh(none, BuildOptions{});
    const CwbvhBvh cw = build_cwbvh(bvh, none);
    check_layout(bvh, none, cw, true);
    EXPECT_EQ(cw.memory_bytes(), 0u);
    const Ray ray{Vec3f(0.0f), 0.0f, Vec3f(0, 0, 1)};
    EXPECT_FALSE(cwbvh_intersect(cw.view(), ray).found());
    EXPECT_FALSE(cwbvh_occluded(cw.view(), ray));
    EXPECT_FALSE(cwbvh_intersect(CwbvhView{}, ray).found());
}

// Eight small triangles at the corners of a cube: one root with eight leaf
// slots, slot s holding the corner that rays with direction signs s (bit set
// = negative) meet first, i.e. the corner on the positive side where s has a
// bit. Rays from outside a corner test that corner's triangle first.
TEST(Cwbvh, SlotsFollowTheDirectionOctants) {
    SceneGeometry g;
    for (int c = 0; c < 8; ++c) {
        const Vec3f centre((c & 1) ? 5.0f : -5.0f, (c & 2) ? 5.0f : -5.0f, (c & 4) ? 5.0f : -5.0f);
        test::append(g, {centre + Vec3f(-1, -1, 0), centre + Vec3f(1, -1, 0), centre + Vec3f(0, 1, 0)});
    }
    const Bvh bvh = build_bvh(g.triangles, BuildOptions{.max_leaf_size = 1});
    const CwbvhBvh cw = build_cwbvh(bvh, g.triangles);
    check_layout(bvh, g.triangles, cw, true);
    ASSERT_EQ(cw.nodes.size(), 1u);
    const CwbvhNode& root = cw.nodes[0];
    for (int s = 0; s < 8; ++s) {
        ASSERT_NE(root.meta[s], kCwbvhEmptyMeta);
        ASSERT_FALSE(cwbvh_meta_is_inner(root.meta[s]));
        const CwbvhTriangle& t = cw.triangles[root.base_index_triangle + (root.meta[s] & 31u)];
        EXPECT_EQ(bits(t.v0.w), uint32_t(s)) << "slot " << s;
    }
    // A ray through all eight boxes' region along a diagonal tests its
    // nearest corner first: with direction signs s it enters corner s first.
    for (int s = 0; s < 8; ++s) {
        const Vec3f dir((s & 1) ? -1.0f : 1.0f, (s & 2) ? -1.0f : 1.0f, (s & 4) ? -1.0f : 1.0f);
        const Vec3f centre((s & 1) ? 5.0f : -5.0f, (s & 2) ? 5.0f : -5.0f, (s & 4) ? 5.0f : -5.0f);
        const Ray ray{centre - dir * 3.0f, 0.0f, dir};
        CwbvhCounters counters;
        const Hit hit = cwbvh_intersect_counted(cw.view(), ray, counters);
        ASSERT_TRUE(hit.found());
        EXPECT_EQ(hit.prim, uint32_t(s));
        EXPECT_EQ(counters.nodes_visited, 1u);
        EXPECT_EQ(counters.boxes_tested, 8u);
    }
}

// Eight clusters at the cube corners, each a stack of 12 triangles facing
// the cube's centre, so every root slot is an inner node. A ray along a
// diagonal passes through its own corner's stack and then the opposite one;
// visiting the children in octant order finds the hit in the near stack
// first, after which the far stack's boxes lie beyond tmax: only the near
// stack's triangles are tested. The reverse order would test both.
TEST(Cwbvh, InnerChildrenAreVisitedInOctantOrder) {
    constexpr int kPerCluster = 12;
    SceneGeometry g;
    for (int c = 0; c < 8; ++c) {
        const Vec3f corner((c & 1) ? 1.0f : -1.0f, (c & 2) ? 1.0f : -1.0f, (c & 4) ? 1.0f : -1.0f);
        const Vec3f axis = normalize(corner);
        const Vec3f u = normalize(cross(axis, Vec3f(0, 0, 1) + Vec3f(0.3f, 0, 0)));
        const Vec3f v = cross(axis, u);
        for (int k = 0; k < kPerCluster; ++k) {
            const Vec3f centre = corner * 5.0f + axis * (0.1f * float(k) - 0.6f);
            test::append(g, {centre - u - v, centre + u * 1.5f, centre + v * 1.5f});
        }
    }
    g.normal_matrices.push_back(Affine3f::identity());
    const Bvh bvh = build_bvh(g.triangles, BuildOptions{.max_leaf_size = 1});
    const CwbvhBvh cw = build_cwbvh(bvh, g.triangles);
    check_layout(bvh, g.triangles, cw, true);
    EXPECT_EQ(cw.nodes[0].imask, 0xFF);
    const BruteForceAccel brute(g);
    for (int s = 0; s < 8; ++s) {
        const Vec3f dir((s & 1) ? -1.0f : 1.0f, (s & 2) ? -1.0f : 1.0f, (s & 4) ? -1.0f : 1.0f);
        const Ray ray{dir * -9.0f, 0.0f, dir};
        CwbvhCounters counters;
        const Hit hit = cwbvh_intersect_counted(cw.view(), ray, counters);
        const Hit expected = brute.intersect(ray);
        ASSERT_TRUE(expected.found());
        EXPECT_EQ(hit.prim, expected.prim);
        EXPECT_EQ(hit.prim / kPerCluster, uint32_t(s));  // the near stack, nearest triangle
        EXPECT_LE(counters.prims_tested, uint32_t(kPerCluster)) << "octant " << s;
    }
}

// A caterpillar of `inner` canonical inner nodes (as in aila_laine_test.cpp):
// inner node k has leaf triangle k on the left and the rest of the chain on
// the right.
Bvh make_chain(int inner, std::vector<Triangle>& triangles) {
    triangles.clear();
    for (int k = 0; k <= inner; ++k) {
        const auto x = static_cast<float>(k);
        triangles.push_back({Vec3f(x, -1, -1), Vec3f(x, 1, -1), Vec3f(x, 0, 1)});
    }
    Bvh bvh;
    bvh.nodes.resize(2 * static_cast<size_t>(inner) + 1);
    for (int k = 0; k <= inner; ++k) bvh.prim_indices.push_back(static_cast<uint32_t>(k));
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

TEST(Cwbvh, DeepestCanonicalChainStaysWithinTheStack) {
    std::vector<Triangle> triangles;
    const Bvh bvh = make_chain(kBvhMaxDepth, triangles);
    const CwbvhBvh cw = build_cwbvh(bvh, triangles);
    check_layout(bvh, triangles, cw, true);
    EXPECT_LE(cw.depth, kBvhMaxDepth / 4);
    const Ray ray{Vec3f(kBvhMaxDepth + 10.0f, 0.1f, 0.0f), 0.0f, Vec3f(-1, 0, 0)};
    const Hit hit = cwbvh_intersect(cw.view(), ray);
    ASSERT_TRUE(hit.found());
    EXPECT_EQ(hit.prim, static_cast<uint32_t>(kBvhMaxDepth));
    EXPECT_EQ(hit.t, 10.0f);
    EXPECT_TRUE(cwbvh_occluded(cw.view(), ray));
    const Ray forward{Vec3f(-0.5f, 0.1f, 0.0f), 0.0f, Vec3f(1, 0, 0)};
    EXPECT_EQ(cwbvh_intersect(cw.view(), forward).prim, 0u);

    // Every wide node but the last has leaves and one inner child, and the
    // ray hits them all: postponing every triangle group piles up one per
    // level above the deepest, whose own triangles find the hit.
    AlwaysPostpone always;
    const Hit postponed = cwbvh_intersect(cw.view(), ray, always);
    EXPECT_EQ(postponed.prim, static_cast<uint32_t>(kBvhMaxDepth));
    EXPECT_EQ(postponed.t, 10.0f);
    EXPECT_EQ(always.max_stack, cw.depth - 1);
    EXPECT_EQ(always.postponed, size_t(cw.depth - 1));
    AlwaysPostpone always_any;
    EXPECT_TRUE(cwbvh_occluded(cw.view(), ray, always_any));
    const Ray short_ray{ray.org, 0.0f, ray.dir, 9.5f};  // stops before the nearest triangle
    EXPECT_FALSE(cwbvh_occluded(cw.view(), short_ray, always_any));
    EXPECT_FALSE(cwbvh_intersect(cw.view(), short_ray, always_any).found());
}

TEST(Cwbvh, MalformedBvhThrows) {
    std::vector<Triangle> triangles;
    const Bvh good = make_chain(3, triangles);
    EXPECT_NO_THROW(build_cwbvh(good, triangles));
    Bvh bad_child = good;
    bad_child.nodes[0].first = static_cast<uint32_t>(good.nodes.size() - 1);
    EXPECT_THROW(build_cwbvh(bad_child, triangles), Error);
    Bvh cycle = good;
    cycle.nodes[2].first = 0;
    EXPECT_THROW(build_cwbvh(cycle, triangles), Error);
    Bvh bad_prim = good;
    bad_prim.prim_indices[1] = 99;
    EXPECT_THROW(build_cwbvh(bad_prim, triangles), Error);
    Bvh bad_range = good;
    bad_range.nodes[1].count = 50;
    EXPECT_THROW(build_cwbvh(bad_range, triangles), Error);
}

// Work per ray on a 20k-triangle sphere seen from outside, against the
// canonical BVH it was built from (printed for the record).
TEST(Cwbvh, CountersShowLogarithmicWork) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(5), 3.0f);
    ASSERT_GT(sphere.triangles.size(), 10000u);
    const Bvh bvh = build_bvh(sphere.triangles, BuildOptions{});
    const CwbvhBvh cw = build_cwbvh(bvh, sphere.triangles);
    check_layout(bvh, sphere.triangles, cw, true);
    const BvhView canonical{bvh.nodes.data(), bvh.prim_indices.data(), sphere.triangles.data(),
                            static_cast<uint32_t>(bvh.nodes.size())};
    const std::vector<Ray> rays = test::make_rays(sphere, 4000, 9);
    CwbvhCounters wide;
    TraversalCounters binary;
    uint32_t max_nodes = 0;
    for (const Ray& ray : rays) {
        CwbvhCounters one;
        const Hit got = cwbvh_intersect_counted(cw.view(), ray, one);
        const Hit reference = bvh_intersect_counted(canonical, ray, binary);
        ASSERT_EQ(got.found(), reference.found());
        wide.nodes_visited += one.nodes_visited;
        wide.boxes_tested += one.boxes_tested;
        wide.prims_tested += one.prims_tested;
        max_nodes = std::max(max_nodes, one.nodes_visited);
        EXPECT_LT(one.nodes_visited + one.prims_tested, sphere.triangles.size() / 20);
    }
    const double n = double(rays.size());
    std::printf("cwbvh: %zu triangles, %zu nodes (%zu bytes + %zu triangle bytes), depth %d, %zu leaves\n",
                sphere.triangles.size(), cw.nodes.size(), cw.nodes.size() * sizeof(CwbvhNode),
                cw.triangles.size() * sizeof(CwbvhTriangle), cw.depth, cw.leaf_count);
    std::printf("canonical: %zu nodes (%zu bytes)\n", bvh.nodes.size(), bvh.memory_bytes());
    std::printf("per ray: cwbvh %.2f nodes, %.2f boxes, %.2f triangles; canonical %.2f boxes, %.2f triangles\n",
                wide.nodes_visited / n, wide.boxes_tested / n, wide.prims_tested / n, binary.nodes_visited / n,
                binary.prims_tested / n);
    // Wide nodes replace about three binary levels each.
    EXPECT_LT(double(wide.nodes_visited), 0.5 * double(binary.nodes_visited));
    EXPECT_LT(max_nodes, 200u);
}

// ---- Slot assignment (section 4.2): the auction against brute force ----

using CostTable = double[kCwbvhWidth][kCwbvhWidth];

double assignment_cost(const CostTable& cost, int count, const int (&slot_of)[kCwbvhWidth]) {
    double total = 0.0;
    for (int c = 0; c < count; ++c) total += cost[c][slot_of[c]];
    return total;
}

// Every slot in range and none used twice.
bool is_injective(int count, const int (&slot_of)[kCwbvhWidth]) {
    unsigned used = 0;
    for (int c = 0; c < count; ++c) {
        if (slot_of[c] < 0 || slot_of[c] >= kCwbvhWidth || ((used >> slot_of[c]) & 1u)) return false;
        used |= 1u << slot_of[c];
    }
    return true;
}

// Least total over all 8! / (8 - count)! injective assignments (depth first,
// children in order, each taking a free slot).
double brute_force_optimum(const CostTable& cost, int count) {
    double best = INFINITY;
    struct Search {
        const CostTable& cost;
        int count;
        double& best;
        void run(int child, unsigned used, double sum) {
            if (child == count) {
                best = std::min(best, sum);
                return;
            }
            for (int s = 0; s < kCwbvhWidth; ++s) {
                if (!((used >> s) & 1u)) run(child + 1, used | (1u << s), sum + cost[child][s]);
            }
        }
    };
    Search{cost, count, best}.run(0, 0u, 0.0);
    return best;
}

double cost_range(const CostTable& cost, int count) {
    double lo = INFINITY, hi = -INFINITY;
    for (int c = 0; c < count; ++c) {
        for (int s = 0; s < kCwbvhWidth; ++s) {
            lo = std::min(lo, cost[c][s]);
            hi = std::max(hi, cost[c][s]);
        }
    }
    return hi - lo;
}

// Thousands of random tables of every kind: continuous, small integers
// (many ties), all equal, huge magnitudes, and the real geometric costs of
// random child boxes. The auction is a valid assignment within its
// documented 1e-6 * range of the optimum (exactly optimal for integer
// costs, whose distinct totals differ by at least 1), never worse than
// greedy; greedy must be strictly worse on some tables.
TEST(CwbvhAuction, MatchesTheBruteForceOptimum) {
    std::mt19937 rng(2017);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    int greedy_worse = 0, integer_tables = 0;
    constexpr int kTables = 3000;
    for (int table = 0; table < kTables; ++table) {
        const int count = 1 + int(rng() % 8u);
        const int kind = table % 5;
        CostTable cost;
        if (kind == 4) {
            Box3f boxes[kCwbvhWidth];
            for (int c = 0; c < count; ++c) {
                const Vec3f lo(float(unit(rng)), float(unit(rng)), float(unit(rng)));
                boxes[c] = {lo, lo + Vec3f(float(unit(rng)), float(unit(rng)), float(unit(rng))) * 0.5f};
            }
            cwbvh_slot_costs(boxes, count, cost);
        } else {
            const double scale = kind == 3 ? 1e30 : 1.0;
            for (int c = 0; c < count; ++c) {
                for (int s = 0; s < kCwbvhWidth; ++s) {
                    switch (kind) {
                    case 0: cost[c][s] = unit(rng) * 2.0 - 1.0; break;
                    case 1: cost[c][s] = double(rng() % 4u); break;            // ties everywhere
                    case 2: cost[c][s] = table % 2 ? 7.0 : double(rng() % 2u); break;  // all equal, or 0/1
                    default: cost[c][s] = scale * (unit(rng) - 0.5); break;
                    }
                }
            }
        }
        int auction[kCwbvhWidth], greedy[kCwbvhWidth];
        cwbvh_assign_slots_auction(cost, count, auction);
        cwbvh_assign_slots_greedy(cost, count, greedy);
        ASSERT_TRUE(is_injective(count, auction)) << "table " << table;
        ASSERT_TRUE(is_injective(count, greedy)) << "table " << table;
        const double optimum = brute_force_optimum(cost, count);
        const double range = cost_range(cost, count);
        const double got = assignment_cost(cost, count, auction);
        const double greedy_total = assignment_cost(cost, count, greedy);
        if (kind == 1 || kind == 2) {
            ++integer_tables;
            EXPECT_EQ(got, optimum) << "table " << table << " count " << count;
        } else {
            // The bound, plus rounding of the sums of eight doubles.
            const double tolerance = 1e-6 * range + 1e-13 * count * (std::fabs(optimum) + range);
            EXPECT_LE(got, optimum + tolerance) << "table " << table << " count " << count;
        }
        EXPECT_GE(got, optimum - 1e-13 * count * (std::fabs(optimum) + range));
        EXPECT_LE(got, greedy_total + 1e-6 * range) << "table " << table;
        if (greedy_total > optimum + 1e-3 * range) ++greedy_worse;
    }
    EXPECT_GT(integer_tables, kTables / 3);
    EXPECT_GT(greedy_worse, kTables / 50) << "greedy would pass for the auction";
}

// A table where greedy, taking the cheapest pair (child 0, slot 0) first,
// leaves child 1 only its expensive slots; the optimum gives slot 0 to child 1.
TEST(CwbvhAuction, BeatsGreedyWhereTheCheapestPairIsWrong) {
    CostTable cost;
    for (int s = 0; s < kCwbvhWidth; ++s) {
        cost[0][s] = s == 0 ? 0.0 : 1.0;
        cost[1][s] = s == 0 ? 0.1 : 10.0;
    }
    int auction[kCwbvhWidth], greedy[kCwbvhWidth];
    cwbvh_assign_slots_greedy(cost, 2, greedy);
    cwbvh_assign_slots_auction(cost, 2, auction);
    EXPECT_EQ(greedy[0], 0);
    EXPECT_DOUBLE_EQ(assignment_cost(cost, 2, greedy), 10.0);
    EXPECT_EQ(auction[1], 0);
    EXPECT_NE(auction[0], 0);
    EXPECT_DOUBLE_EQ(assignment_cost(cost, 2, auction), 1.1);
}

// Inputs that break naive auctions: all ties (every bid raises a price by
// eps only), costs near the double range (hi - lo overflows unless scaled),
// subnormal differences, non-finite entries. All must terminate with a
// valid assignment; finite entries win over non-finite ones where possible.
TEST(CwbvhAuction, DegenerateTablesTerminate) {
    for (int count = 0; count <= kCwbvhWidth; ++count) {
        for (double value : {0.0, -3.0, 1e30, -1e308, 5e-324}) {
            CostTable cost;
            for (auto& row : cost) std::fill(row, row + kCwbvhWidth, value);
            int slot_of[kCwbvhWidth];
            cwbvh_assign_slots_auction(cost, count, slot_of);
            EXPECT_TRUE(is_injective(count, slot_of)) << count << " " << value;
            for (int c = count; c < kCwbvhWidth; ++c) EXPECT_EQ(slot_of[c], -1);
        }
        if (count == 0) continue;
        // Extremes of both signs: the optimum is still found.
        CostTable cost;
        for (int c = 0; c < count; ++c) {
            for (int s = 0; s < kCwbvhWidth; ++s) cost[c][s] = (c + s) % kCwbvhWidth == 0 ? -1.7e308 : 1.7e308;
        }
        int slot_of[kCwbvhWidth];
        cwbvh_assign_slots_auction(cost, count, slot_of);
        ASSERT_TRUE(is_injective(count, slot_of));
        for (int c = 0; c < count; ++c) EXPECT_EQ((c + slot_of[c]) % kCwbvhWidth, 0) << "child " << c;
        // Non-finite costs everywhere except one slot per child.
        for (int c = 0; c < count; ++c) {
            for (int s = 0; s < kCwbvhWidth; ++s) {
                cost[c][s] = s == c ? double(c) : (s % 2 ? INFINITY : NAN);
            }
        }
        cwbvh_assign_slots_auction(cost, count, slot_of);
        ASSERT_TRUE(is_injective(count, slot_of));
        for (int c = 0; c < count; ++c) EXPECT_EQ(slot_of[c], c);
    }
}

// The builder uses the auction: random roots of two to eight single-triangle
// leaves get the optimal octant assignment of their triangle boxes, also
// where greedy would not.
TEST(CwbvhAuction, BuilderAssignsSlotsOptimally) {
    std::mt19937 rng(42);
    std::uniform_real_distribution<float> coordinate(-10.0f, 10.0f);
    std::uniform_real_distribution<float> offset(-1.0f, 1.0f);
    int greedy_worse = 0;
    constexpr int kScenes = 300;
    for (int scene = 0; scene < kScenes; ++scene) {
        const int count = 2 + scene % 7;
        std::vector<Triangle> triangles;
        for (int i = 0; i < count; ++i) {
            const Vec3f c(coordinate(rng), coordinate(rng), coordinate(rng));
            triangles.push_back({c + Vec3f(offset(rng), offset(rng), offset(rng)),
                                 c + Vec3f(offset(rng), offset(rng), offset(rng)),
                                 c + Vec3f(offset(rng), offset(rng), offset(rng))});
        }
        const Bvh bvh = build_bvh(triangles, BuildOptions{.max_leaf_size = 1});
        const CwbvhBvh cw = build_cwbvh(bvh, triangles);
        ASSERT_EQ(cw.nodes.size(), 1u) << "scene " << scene;
        const CwbvhNode& root = cw.nodes[0];
        int slot_of[kCwbvhWidth];
        int leaves = 0;
        for (int s = 0; s < kCwbvhWidth; ++s) {
            if (root.meta[s] == kCwbvhEmptyMeta) continue;
            ASSERT_EQ(root.meta[s] >> 5, 1) << "one triangle per leaf";
            const uint32_t prim = bits(cw.triangles[root.base_index_triangle + (root.meta[s] & 31u)].v0.w);
            ASSERT_LT(prim, uint32_t(count));
            slot_of[prim] = s;
            ++leaves;
        }
        ASSERT_EQ(leaves, count);
        Box3f boxes[kCwbvhWidth];
        for (int i = 0; i < count; ++i) boxes[i] = triangles[size_t(i)].bounds();
        CostTable cost;
        cwbvh_slot_costs(boxes, count, cost);
        const double optimum = brute_force_optimum(cost, count);
        const double range = cost_range(cost, count);
        EXPECT_LE(assignment_cost(cost, count, slot_of), optimum + 1e-6 * range) << "scene " << scene;
        int greedy[kCwbvhWidth];
        cwbvh_assign_slots_greedy(cost, count, greedy);
        if (assignment_cost(cost, count, greedy) > optimum + 1e-3 * range) ++greedy_worse;
    }
    EXPECT_GT(greedy_worse, 0);
}

}  // namespace
}  // namespace rf
