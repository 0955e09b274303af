// Morton-ordered BVH builders: LBVH (Karras 2012, 30/63-bit), HLBVH2
// (Garanzha 2014 ch. 5), PLOC (Meister and Bittner 2018) and H-PLOC (Benthin et al. 2024). Morton encoders
// and the radix sort against simple references; structural invariants of the
// canonical BVH; the depth limit on pathological input; determinism across
// thread counts; traversal against brute force; SAH comparisons.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/lbvh.h"
#include "accel/bvh/builders/morton_code.h"
#include "accel/bvh/builders/morton_radix_sort.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel/bvh/builders/ploc.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "bvh_invariants.h"
#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

// ---------------------------------------------------------------- helpers

using test::check_bvh;
using test::identical;
using test::same_box;
using test::TreeShape;

// Through the dispatch, which runs the builder on options.threads threads.
Bvh build_with(Builder builder, std::span<const Triangle> triangles, BuildOptions options) {
    switch (builder) {
        case Builder::Lbvh30:
        case Builder::Lbvh63:
        case Builder::Hlbvh2:
        case Builder::Ploc:
        case Builder::Hploc: options.builder = builder; return build_bvh(triangles, options);
        default: ADD_FAILURE() << "not a Morton builder"; return {};
    }
}

// Unit triangles at x = 1.09^i (as in bvh_build_test.cpp).
SceneGeometry make_geometric_row(int count, float factor = 1.09f) {
    SceneGeometry g;
    float x = 1.0f;
    for (int i = 0; i < count; ++i, x *= factor) test::append(g, {Vec3f(x, 0, 0), Vec3f(x, 1, 0), Vec3f(x, 0, 1)});
    return g;
}

SceneGeometry make_identical(int count) {
    SceneGeometry g;
    for (int i = 0; i < count; ++i) test::append(g, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    return g;
}

using test::make_morton_chain;

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
    scenes.push_back({"identical", make_identical(100)});
    SceneGeometry points;
    for (int i = 0; i < 50; ++i) test::append(points, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    scenes.push_back({"points", std::move(points)});
    return scenes;
}

void check_invariants(Builder builder) {
    for (const NamedScene& scene : test_scenes()) {
        for (int leaf_size : {1, 4, 16}) {
            for (int threads : {1, 2}) {
                SCOPED_TRACE(scene.name + " leaf " + std::to_string(leaf_size) + " threads " + std::to_string(threads));
                const BuildOptions options{.threads = threads, .max_leaf_size = leaf_size};
                check_bvh(build_with(builder, scene.geometry.triangles, options), scene.geometry.triangles, leaf_size);
            }
        }
    }
}

void check_depth_limit(Builder builder) {
    for (const SceneGeometry& g : {make_geometric_row(900), make_geometric_row(120, 2.0f), make_identical(10000),
                                   make_morton_chain(2000)}) {
        for (int leaf_size : {1, 4}) {
            const Bvh bvh = build_with(builder, g.triangles, BuildOptions{.max_leaf_size = leaf_size});
            const TreeShape shape = check_bvh(bvh, g.triangles, leaf_size);
            EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        }
    }
}

void check_deterministic(Builder builder) {
    // Several radix-sort blocks and parallel tasks.
    const SceneGeometry soup = test::make_triangle_soup(100000, 5, {Vec3f(-100.0f), Vec3f(100.0f)}, 1.0f);
    const Bvh one = build_with(builder, soup.triangles, BuildOptions{.threads = 1});
    const Bvh two = build_with(builder, soup.triangles, BuildOptions{.threads = 2});
    const Bvh all = build_with(builder, soup.triangles, BuildOptions{.threads = 0});
    EXPECT_TRUE(identical(one, two));
    EXPECT_TRUE(identical(one, all));
    check_bvh(one, soup.triangles, 4);
}

void check_empty_and_single(Builder builder) {
    const Bvh empty = build_with(builder, {}, BuildOptions{});
    EXPECT_TRUE(empty.nodes.empty());
    EXPECT_TRUE(empty.prim_indices.empty());
    const Triangle tri{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)};
    const Bvh one = build_with(builder, std::span<const Triangle>(&tri, 1), BuildOptions{});
    ASSERT_EQ(one.nodes.size(), 1u);
    EXPECT_EQ(one.nodes[0].count, 1u);
    EXPECT_TRUE(same_box(one.nodes[0].bounds, tri.bounds()));
    const Triangle two[2] = {tri, {Vec3f(5, 0, 0), Vec3f(6, 0, 0), Vec3f(5, 1, 0)}};
    check_bvh(build_with(builder, two, BuildOptions{.max_leaf_size = 1}), two, 1);
}

// Ray mix as in bvh_traversal_test.cpp: random, aimed at triangles, axis-aligned, limited.
using test::make_rays;

void compare_with_brute_force(const SceneGeometry& g, const BuildOptions& options, size_t ray_count,
                              uint32_t seed) {
    const auto accel = build_accel(g, options);
    const BruteForceAccel brute(g);
    size_t hits = 0, failures = 0;
    for (const Ray& ray : make_rays(g, ray_count, seed)) {
        const Hit expected = brute.intersect(ray);
        const Hit got = accel->intersect(ray);
        const bool ok_found = got.found() == expected.found();
        bool ok = ok_found && accel->occluded(ray) == expected.found();
        if (ok_found && expected.found()) {
            if (got.prim != expected.prim) {
                ok = ok && std::fabs(got.t - expected.t) <= 1e-5f * std::fabs(expected.t);
            } else {
                ok = ok && got.t == expected.t && got.u == expected.u && got.v == expected.v;
            }
            ok = ok && got.t >= ray.tmin && got.t <= ray.tmax;
        }
        if (!ok && ++failures <= 5) {
            ADD_FAILURE() << "ray mismatch: found " << got.found() << "/" << expected.found() << " prim " << got.prim
                          << "/" << expected.prim << " t " << got.t << "/" << expected.t;
        }
        hits += expected.found();
    }
    EXPECT_EQ(failures, 0u);
    EXPECT_GT(hits, ray_count / 5);
    EXPECT_LT(hits, ray_count);
}

void check_traversal(Builder builder) {
    const SceneGeometry soup = test::make_triangle_soup(4000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    for (int leaf : {1, 4, 8}) {
        SCOPED_TRACE("soup leaf " + std::to_string(leaf));
        compare_with_brute_force(soup, BuildOptions{.builder = builder, .max_leaf_size = leaf}, 800, 1);
    }
    {
        SCOPED_TRACE("sphere");
        compare_with_brute_force(test::to_geometry(test::make_icosphere(4), 3.0f), BuildOptions{.builder = builder},
                                 1500, 2);
    }
    {
        SCOPED_TRACE("nasty");
        compare_with_brute_force(test::make_nasty_geometry(4), BuildOptions{.builder = builder, .max_leaf_size = 2},
                                 2000, 3);
    }
    {
        SCOPED_TRACE("far soup");
        const SceneGeometry far = test::make_triangle_soup(2000, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
        compare_with_brute_force(far, BuildOptions{.builder = builder}, 1500, 4);
    }
}

// ---------------------------------------------------------------- MortonCode

uint32_t reference_morton_30(uint32_t x, uint32_t y, uint32_t z) {
    uint32_t code = 0;
    for (int k = 0; k < 10; ++k) {
        code |= ((x >> k) & 1u) << (3 * k + 2);
        code |= ((y >> k) & 1u) << (3 * k + 1);
        code |= ((z >> k) & 1u) << (3 * k);
    }
    return code;
}

uint64_t reference_morton_63(uint64_t x, uint64_t y, uint64_t z) {
    uint64_t code = 0;
    for (int k = 0; k < 21; ++k) {
        code |= ((x >> k) & 1u) << (3 * k + 2);
        code |= ((y >> k) & 1u) << (3 * k + 1);
        code |= ((z >> k) & 1u) << (3 * k);
    }
    return code;
}

TEST(MortonCode, Encode30MatchesBitByBitReference) {
    std::mt19937 rng(1);
    std::uniform_int_distribution<uint32_t> cell(0, 1023);
    for (uint32_t edge : {0u, 1u, 512u, 1023u}) {
        EXPECT_EQ(morton_encode_30(edge, edge, edge), reference_morton_30(edge, edge, edge));
    }
    EXPECT_EQ(morton_encode_30(1023, 1023, 1023), (1u << 30) - 1);
    EXPECT_EQ(morton_encode_30(1, 0, 0), 4u);
    for (int i = 0; i < 20000; ++i) {
        const uint32_t x = cell(rng), y = cell(rng), z = cell(rng);
        ASSERT_EQ(morton_encode_30(x, y, z), reference_morton_30(x, y, z)) << x << " " << y << " " << z;
    }
}

TEST(MortonCode, Encode63MatchesBitByBitReference) {
    std::mt19937_64 rng(2);
    std::uniform_int_distribution<uint64_t> cell(0, (1u << 21) - 1);
    EXPECT_EQ(morton_encode_63((1u << 21) - 1, (1u << 21) - 1, (1u << 21) - 1), (uint64_t{1} << 63) - 1);
    EXPECT_EQ(morton_encode_63(0, 0, 1), 1u);
    for (int i = 0; i < 20000; ++i) {
        const uint64_t x = cell(rng), y = cell(rng), z = cell(rng);
        ASSERT_EQ(morton_encode_63(x, y, z), reference_morton_63(x, y, z)) << x << " " << y << " " << z;
    }
}

TEST(MortonCode, QuantizerClampsAndHandlesFlatAxes) {
    const MortonQuantizer q(Box3f{Vec3f(0.0f, 5.0f, -1.0f), Vec3f(1.0f, 5.0f, 1.0f)}, 10);
    EXPECT_EQ(q.cell(0.0f, 0), 0u);
    EXPECT_EQ(q.cell(1.0f, 0), 1023u);  // the far border lands in the last cell
    EXPECT_EQ(q.cell(0.5f, 0), 512u);
    EXPECT_EQ(q.cell(-3.0f, 0), 0u);
    EXPECT_EQ(q.cell(7.0f, 0), 1023u);
    EXPECT_EQ(q.cell(5.0f, 1), 0u);  // flat axis
    EXPECT_EQ(q.cell(NAN, 2), 0u);
    EXPECT_EQ(q.code30(Vec3f(1.0f, 5.0f, 1.0f)), morton_encode_30(1023, 0, 1023));
}

template <class Key>
void check_radix_sort(size_t n, int bits, Key max_key, uint32_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_int_distribution<Key> any(0, max_key);
    std::vector<Key> keys(n);
    std::vector<uint32_t> values(n);
    for (size_t i = 0; i < n; ++i) {
        keys[i] = any(rng);
        values[i] = static_cast<uint32_t>(i);
    }
    if (n > 10) {  // many duplicates, and runs that share low digits
        for (size_t i = 0; i < n / 3; ++i) keys[i] = keys[i % 7];
    }
    std::vector<std::pair<Key, uint32_t>> expected(n);
    for (size_t i = 0; i < n; ++i) expected[i] = {keys[i], values[i]};
    std::stable_sort(expected.begin(), expected.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    radix_sort_pairs(keys, values, bits);
    for (size_t i = 0; i < n; ++i) {
        ASSERT_EQ(keys[i], expected[i].first) << i;
        ASSERT_EQ(values[i], expected[i].second) << i;
    }
}

TEST(MortonCode, RadixSortMatchesStableSort) {
    for (size_t n : {size_t{0}, size_t{1}, size_t{2}, size_t{1000}, size_t{200000}}) {
        SCOPED_TRACE(n);
        check_radix_sort<uint32_t>(n, 30, (1u << 30) - 1, 3);
        check_radix_sort<uint64_t>(n, 63, (uint64_t{1} << 63) - 1, 4);
        check_radix_sort<uint32_t>(n, 30, 5, 5);           // only low digits vary: passes skipped
        check_radix_sort<uint64_t>(n, 63, 1u << 20, 6);
    }
    std::vector<uint32_t> keys(3), values(2);
    EXPECT_THROW(radix_sort_pairs(keys, values, 30), Error);
}

TEST(MortonCode, FusedSortMatchesCodesSortAndGather) {
    // RawTree::sort_by_morton_codes (boxes computed once, 30-bit codes sorted
    // packed) gives what the separate steps give, for both code lengths.
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(5));
    const SceneGeometry same = make_identical(100);  // every code equal: order kept
    for (const SceneGeometry* g : {&sphere, &same}) {
        const BvhBuildConfig config;
        {
            std::vector<uint32_t> keys, order;
            morton::compute_morton_codes(g->triangles, keys, order);
            radix_sort_pairs(keys, order, 30);
            morton::RawTree reference(g->triangles, config), fused(g->triangles, config);
            reference.set_order(std::vector<uint32_t>(order));
            morton::Buffer<uint32_t> fused_keys;
            fused.sort_by_morton_codes(fused_keys);
            ASSERT_EQ(fused.size(), order.size());
            ASSERT_EQ(fused_keys.size(), keys.size());
            for (size_t i = 0; i < keys.size(); ++i) {
                ASSERT_EQ(fused_keys[i], keys[i]) << i;
                ASSERT_EQ(fused.order[i], order[i]) << i;
                ASSERT_TRUE(same_box(fused.boxes[i], reference.boxes[i])) << i;
            }
        }
        {
            std::vector<uint64_t> keys;
            std::vector<uint32_t> order;
            morton::compute_morton_codes(g->triangles, keys, order);
            radix_sort_pairs(keys, order, 63);
            morton::RawTree fused(g->triangles, config);
            morton::Buffer<uint64_t> fused_keys;
            fused.sort_by_morton_codes(fused_keys);
            ASSERT_EQ(fused_keys.size(), keys.size());
            for (size_t i = 0; i < keys.size(); ++i) {
                ASSERT_EQ(fused_keys[i], keys[i]) << i;
                ASSERT_EQ(fused.order[i], order[i]) << i;
                ASSERT_TRUE(same_box(fused.boxes[i], g->triangles[order[i]].bounds())) << i;
            }
        }
    }
    morton::RawTree empty(std::span<const Triangle>{}, BvhBuildConfig{});
    morton::Buffer<uint32_t> keys;
    empty.sort_by_morton_codes(keys);
    EXPECT_EQ(empty.size(), 0u);
    EXPECT_TRUE(keys.empty());
}

TEST(Lbvh, InOrderEmissionMatchesGeneralEmission) {
    // emit_in_order (the primitive order moved in) writes the same BVH as emit.
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    for (int leaf_size : {1, 4}) {
        const BvhBuildConfig config{.max_leaf_size = leaf_size};
        const Bvh lbvh = parallel::with_threads(1, [&] { return build_lbvh(sphere.triangles, config, 30); });
        // A chain over sorted positions: a tree whose leaves are in order.
        auto chain = [&](morton::RawTree& tree) {
            std::vector<uint32_t> order(sphere.triangles.size());
            for (uint32_t i = 0; i < order.size(); ++i) order[i] = static_cast<uint32_t>(order.size() - 1 - i);
            tree.set_order(std::move(order));
            const uint32_t n = tree.size();
            tree.nodes.resize(n - 1);
            tree.finalize(n - 2, morton::kLeafRef | (n - 2), morton::kLeafRef | (n - 1));
            for (uint32_t k = n - 2; k-- > 0;) tree.finalize(k, morton::kLeafRef | k, k + 1);
        };
        morton::RawTree a(sphere.triangles, config), b(sphere.triangles, config);
        chain(a);
        chain(b);
        const Bvh general = a.emit(0), in_order = b.emit_in_order(0);
        ASSERT_EQ(general.nodes.size(), in_order.nodes.size());
        EXPECT_EQ(general.prim_indices, in_order.prim_indices);
        for (size_t i = 0; i < general.nodes.size(); ++i) {
            EXPECT_TRUE(same_box(general.nodes[i].bounds, in_order.nodes[i].bounds)) << i;
            EXPECT_EQ(general.nodes[i].first, in_order.nodes[i].first) << i;
            EXPECT_EQ(general.nodes[i].count, in_order.nodes[i].count) << i;
        }
        check_bvh(in_order, sphere.triangles, leaf_size);
        check_bvh(lbvh, sphere.triangles, leaf_size);
    }
}

// ---------------------------------------------------------------- Lbvh

TEST(Lbvh, InvariantsHoldForScenesLeafSizesAndThreads) {
    check_invariants(Builder::Lbvh30);
    check_invariants(Builder::Lbvh63);
}

TEST(Lbvh, DepthStaysWithinLimitOnPathologicalInput) {
    check_depth_limit(Builder::Lbvh30);
    check_depth_limit(Builder::Lbvh63);
}

TEST(Lbvh, DeepMortonChainIsCutAtTheDepthLimit) {
    const SceneGeometry chain = make_morton_chain(2000);
    for (int leaf_size : {1, 4}) {
        const TreeShape shape = check_bvh(build_lbvh(chain.triangles, BvhBuildConfig{.max_leaf_size = leaf_size}, 63),
                                          chain.triangles, leaf_size);
        EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        EXPECT_GE(shape.max_depth, 60);  // the 63-level chain is really there
    }
}

TEST(Lbvh, SameTreeForEveryThreadCount) {
    check_deterministic(Builder::Lbvh30);
    check_deterministic(Builder::Lbvh63);
}

TEST(Lbvh, EmptySingleAndPair) {
    check_empty_and_single(Builder::Lbvh30);
    check_empty_and_single(Builder::Lbvh63);
}

TEST(Lbvh, MatchesBruteForce) {
    check_traversal(Builder::Lbvh30);
    check_traversal(Builder::Lbvh63);
}


TEST(Lbvh, SahLeafCollapseNeverCostsMore) {
    // The collapse is a bottom-up optimum of exactly the SAH that Bvh::sah_cost
    // measures, over trees that include the uncollapsed one.
    const SceneGeometry soup = test::make_triangle_soup(20000, 8, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.3f);
    for (int bits : {30, 63}) {
        const Bvh single = build_lbvh(soup.triangles, BvhBuildConfig{.max_leaf_size = 1}, bits);
        const Bvh collapsed = build_lbvh(soup.triangles, BvhBuildConfig{.max_leaf_size = 8}, bits);
        const TreeShape shape = check_bvh(collapsed, soup.triangles, 8);
        EXPECT_GT(shape.multi_prim_leaves, 0u);
        EXPECT_LT(collapsed.nodes.size(), single.nodes.size());
        EXPECT_LE(collapsed.sah_cost(), single.sah_cost() * (1.0 + 1e-5));
    }
}

TEST(Lbvh, Finer63BitCodesSeparateClosePrimitives) {
    // 20 triangles within one 30-bit cell: 30-bit codes all tie (index order),
    // 63-bit codes order them along x.
    SceneGeometry g;
    test::append(g, {Vec3f(0, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1)});
    test::append(g, {Vec3f(1000, 0, 0), Vec3f(1000, 1, 0), Vec3f(1000, 0, 1)});
    for (int i = 19; i >= 0; --i) {
        const float x = 500.0f + 0.01f * static_cast<float>(i);
        test::append(g, {Vec3f(x, 0, 0), Vec3f(x, 1e-3f, 0), Vec3f(x, 0, 1e-3f)});
    }
    const Bvh b63 = build_lbvh(g.triangles, BvhBuildConfig{.max_leaf_size = 1}, 63);
    const Bvh b30 = build_lbvh(g.triangles, BvhBuildConfig{.max_leaf_size = 1}, 30);
    check_bvh(b63, g.triangles, 1);
    check_bvh(b30, g.triangles, 1);
    EXPECT_LT(b63.sah_cost(), b30.sah_cost());
}

TEST(Lbvh, RejectsOtherCodeLengths) {
    const SceneGeometry g = make_identical(3);
    EXPECT_THROW((void)build_lbvh(g.triangles, BvhBuildConfig{}, 32), Error);
}

TEST(Lbvh, DepthLimitRebuildsOnlyDeepSubtrees) {
    // A raw chain of 1000 inner nodes (every node: one triangle + the rest):
    // the emitter must rebuild its deep part balanced and keep the top.
    const SceneGeometry row = make_geometric_row(1000, 1.01f);
    for (int leaf_size : {1, 4}) {
        morton::RawTree tree(row.triangles, BvhBuildConfig{.max_leaf_size = leaf_size});
        std::vector<uint32_t> order(row.triangles.size());
        for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
        tree.set_order(std::move(order));
        const uint32_t n = tree.size();
        tree.nodes.resize(n - 1);
        tree.finalize(n - 2, morton::kLeafRef | (n - 2), morton::kLeafRef | (n - 1));
        for (uint32_t k = n - 2; k-- > 0;) tree.finalize(k, morton::kLeafRef | k, k + 1);
        const Bvh bvh = tree.emit(0);
        const TreeShape shape = check_bvh(bvh, row.triangles, leaf_size);
        EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        EXPECT_GE(shape.max_depth, kBvhMaxDepth - 2);  // the chain is kept as long as it fits
        // The top of the chain is kept: the root's left child is triangle 0 alone.
        ASSERT_GT(bvh.nodes.size(), 2u);
        EXPECT_EQ(bvh.nodes[1].count, 1u);
        EXPECT_EQ(bvh.prim_indices[bvh.nodes[1].first], 0u);
    }
}

// ---------------------------------------------------------------- Hlbvh2

TEST(Hlbvh2, InvariantsHoldForScenesLeafSizesAndThreads) { check_invariants(Builder::Hlbvh2); }
TEST(Hlbvh2, DepthStaysWithinLimitOnPathologicalInput) { check_depth_limit(Builder::Hlbvh2); }
TEST(Hlbvh2, SameTreeForEveryThreadCount) { check_deterministic(Builder::Hlbvh2); }
TEST(Hlbvh2, EmptySingleAndPair) { check_empty_and_single(Builder::Hlbvh2); }
TEST(Hlbvh2, MatchesBruteForce) { check_traversal(Builder::Hlbvh2); }


TEST(Hlbvh2, ClustersAreTheDistinct15BitPrefixesAndStagesAreTimed) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(6));
    std::vector<uint32_t> keys, order;
    morton::compute_morton_codes(sphere.triangles, keys, order);
    std::set<uint32_t> prefixes;
    for (uint32_t k : keys) prefixes.insert(k >> 15);
    Hlbvh2Stages stages;
    const Bvh bvh = build_hlbvh2(sphere.triangles, BvhBuildConfig{}, &stages);
    check_bvh(bvh, sphere.triangles, 4);
    EXPECT_EQ(stages.cluster_count, prefixes.size());
    EXPECT_GT(stages.cluster_count, 100u);
    EXPECT_LE(stages.cluster_count, 32768u);
    for (double ms : {stages.morton_ms, stages.sort_ms, stages.clusters_ms, stages.bottom_ms, stages.top_ms,
                      stages.emit_ms}) {
        EXPECT_GE(ms, 0.0);
    }
    EXPECT_GT(stages.total_ms(), 0.0);
    // The overload without stages builds the same tree.
    EXPECT_TRUE(identical(bvh, build_hlbvh2(sphere.triangles, BvhBuildConfig{})));
}

TEST(Hlbvh2, LeavesHoldAtMostNumLeafTri) {
    const SceneGeometry soup = test::make_triangle_soup(20000, 11, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.3f);
    for (int leaf : {1, 2, 7, 64}) {
        const TreeShape shape = check_bvh(build_hlbvh2(soup.triangles, BvhBuildConfig{.max_leaf_size = leaf}),
                                          soup.triangles, leaf);
        if (leaf > 1) {
            EXPECT_GT(shape.multi_prim_leaves, 0u);
        }
    }
}

// ---------------------------------------------------------------- Ploc

TEST(Ploc, InvariantsHoldForScenesLeafSizesAndThreads) { check_invariants(Builder::Ploc); }
TEST(Ploc, DepthStaysWithinLimitOnPathologicalInput) { check_depth_limit(Builder::Ploc); }
TEST(Ploc, SameTreeForEveryThreadCount) { check_deterministic(Builder::Ploc); }
TEST(Ploc, EmptySingleAndPair) { check_empty_and_single(Builder::Ploc); }
TEST(Ploc, MatchesBruteForce) { check_traversal(Builder::Ploc); }
TEST(Hploc, InvariantsHoldForScenesLeafSizesAndThreads) { check_invariants(Builder::Hploc); }
TEST(Hploc, DepthStaysWithinLimitOnPathologicalInput) { check_depth_limit(Builder::Hploc); }
TEST(Hploc, SameTreeForEveryThreadCountOnSoup) { check_deterministic(Builder::Hploc); }
TEST(Hploc, EmptySingleAndPair) { check_empty_and_single(Builder::Hploc); }
TEST(Hploc, MatchesBruteForce) { check_traversal(Builder::Hploc); }


// Triangles of varying size in Gaussian clusters. (On a uniform volumetric
// soup, greedy merging by box area is no better than Morton order: there
// LBVH and PLOC are within a few percent, and wider radii do slightly worse.)
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

TEST(Ploc, BetterSahThanLbvh) {
    const SceneGeometry soup = make_clustered_soup(30000, 12);
    const double ploc = build_ploc(soup.triangles, BvhBuildConfig{}, PlocOptions{}).sah_cost();
    const double lbvh = build_lbvh(soup.triangles, BvhBuildConfig{}, 30).sah_cost();
    EXPECT_LT(ploc, lbvh);
}

TEST(Ploc, RadiusOptionIsRespected) {
    const SceneGeometry soup = make_clustered_soup(30000, 13);
    const Bvh r1 = build_ploc(soup.triangles, BvhBuildConfig{}, PlocOptions{.radius = 1});
    const Bvh r16 = build_ploc(soup.triangles, BvhBuildConfig{}, PlocOptions{.radius = 16});
    const Bvh r16_again = build_ploc(soup.triangles, BvhBuildConfig{}, PlocOptions{.radius = 16});
    const Bvh r64 = build_ploc(soup.triangles, BvhBuildConfig{}, PlocOptions{.radius = 64});
    check_bvh(r1, soup.triangles, 4);
    check_bvh(r64, soup.triangles, 4);
    EXPECT_TRUE(identical(r16, r16_again));
    EXPECT_FALSE(identical(r1, r16));
    EXPECT_FALSE(identical(r16, r64));
    // A wider search finds closer neighbours: a better tree than radius 1.
    EXPECT_LT(r16.sah_cost(), r1.sah_cost());
    // Radius through build_accel (validated there).
    const auto accel = build_accel(soup, BuildOptions{.builder = Builder::Ploc, .ploc = {.radius = 1}});
    EXPECT_NEAR(accel->stats().sah_cost, r1.sah_cost(), 1e-9 * r1.sah_cost());
    EXPECT_THROW((void)build_accel(soup, BuildOptions{.builder = Builder::Ploc, .ploc = {.radius = 0}}), Error);
}

}  // namespace
}  // namespace rf
