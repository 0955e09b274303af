// Treelet restructuring (Karras and Aila 2013): the dynamic programme
// against every topology of small random treelets; the optimized trees of
// every builder keep the canonical invariants and never a higher SAH cost
// (strictly lower on an LBVH); closest hits equal brute force; the same tree
// for any thread count, and the shared steps replayed one leaf walk at a
// time in shuffled orders (the device's schedule is any order) give it too.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/bvh_build_config.h"
#include "accel/bvh/optimize/treelet_restructure.h"
#include "accel/bvh/optimize/treelet_restructure_steps.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "bvh_invariants.h"
#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using test::check_bvh;
using test::identical;
using test::Refs;

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> scenes() {
    std::vector<NamedScene> out;
    out.push_back({"soup", test::make_triangle_soup(3000, 7, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    out.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    out.push_back({"nasty", test::make_nasty_geometry(3)});
    out.push_back({"far", test::make_triangle_soup(1500, 9, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    SceneGeometry same;
    for (int i = 0; i < 60; ++i) test::append(same, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    out.push_back({"identical", std::move(same)});
    return out;
}

// --- The dynamic programme against exhaustive enumeration -----------------

// The cost of every full binary tree over the leaves in `subset` (formula 2
// with the leaf-size limit, in double), each tree once.
std::vector<double> all_tree_costs(const raw_emit::Costs& sah, const treelet::TreeletLeaves& leaves, uint32_t subset) {
    if ((subset & (subset - 1)) == 0) {
        int i = 0;
        while ((subset >> i) != 1u) ++i;
        return {double(leaves.costs[i])};
    }
    const Box3f box = treelet::subset_box(leaves, subset);
    const double area = double(box.hi.x - box.lo.x) * double(box.hi.y - box.lo.y) +
                        double(box.hi.y - box.lo.y) * double(box.hi.z - box.lo.z) +
                        double(box.hi.z - box.lo.z) * double(box.hi.x - box.lo.x);
    const uint32_t count = treelet::subset_count(leaves, subset);
    const double as_leaf = double(sah.intersection) * area * count;
    std::vector<double> costs;
    const uint32_t lowest = subset & (~subset + 1u), rest = subset ^ lowest;
    for (uint32_t q = 0; q < rest; q = ((q | ~rest) + 1u) & rest) {  // every subset of rest but rest itself
        const uint32_t left = lowest | q;
        for (const double a : all_tree_costs(sah, leaves, left)) {
            for (const double b : all_tree_costs(sah, leaves, subset ^ left)) {
                const double split = sah.traversal * area + a + b;
                costs.push_back(count <= sah.max_leaf_size ? std::min(split, as_leaf) : split);
            }
        }
    }
    return costs;
}

// The cost of the tree the programme's partitions describe, recomputed.
float chosen_tree_cost(const raw_emit::Costs& sah, const treelet::TreeletLeaves& leaves,
                       const treelet::OptimalTopology& topology, uint32_t subset) {
    if ((subset & (subset - 1)) == 0) return topology.cost[subset];
    const uint32_t left = topology.partition[subset];
    EXPECT_NE(left, 0u);
    EXPECT_EQ(left & ~subset, 0u);
    EXPECT_NE(left, subset);
    const float area = raw_emit::half_area(treelet::subset_box(leaves, subset));
    const float split = treelet::split_cost(sah, area, chosen_tree_cost(sah, leaves, topology, left),
                                            chosen_tree_cost(sah, leaves, topology, subset ^ left));
    return treelet::with_leaf_option(sah, area, treelet::subset_count(leaves, subset), split);
}

TEST(TreeletRestructuring, OptimalTopologyMatchesExhaustiveEnumeration) {
    std::mt19937 rng(33);
    std::uniform_real_distribution<float> coord(-10.0f, 10.0f), size(0.01f, 4.0f);
    std::uniform_int_distribution<uint32_t> prims(1, 3);
    for (int n = 3; n <= 6; ++n) {
        for (int trial = 0; trial < 40; ++trial) {
            SCOPED_TRACE("n = " + std::to_string(n) + ", trial " + std::to_string(trial));
            const raw_emit::Costs sah{trial % 2 ? 1.0f : 1.2f, trial % 3 ? 1.0f : 0.4f, trial % 4 == 0 ? 1u : 4u};
            treelet::TreeletLeaves leaves;
            leaves.count = n;
            for (int i = 0; i < n; ++i) {
                const Vec3f lo(coord(rng), coord(rng), coord(rng));
                leaves.boxes[i] = Box3f{lo, lo + Vec3f(size(rng), size(rng), size(rng))};
                leaves.counts[i] = prims(rng);
                // A subtree costs at least its leaf cost's share; vary it so
                // that leaves are not all as cheap as single leaves.
                leaves.costs[i] = raw_emit::leaf_cost(sah, leaves.boxes[i], leaves.counts[i]) * (1.0f + 0.5f * (i % 3));
            }
            treelet::OptimalTopology topology;
            treelet::solve_topology(sah, leaves, topology);
            const uint32_t full = (1u << n) - 1u;
            const std::vector<double> every = all_tree_costs(sah, leaves, full);
            size_t expected_trees = 1;
            for (int k = 3; k <= 2 * n - 3; k += 2) expected_trees *= size_t(k);  // (2n - 3)!!
            EXPECT_EQ(every.size(), expected_trees);
            const double best = *std::min_element(every.begin(), every.end());
            EXPECT_NEAR(topology.cost[full], best, 1e-5 * best);
            EXPECT_EQ(chosen_tree_cost(sah, leaves, topology, full), topology.cost[full]);
        }
    }
}

// --- Whole trees -----------------------------------------------------------

Refs refs_of(Builder builder) {
    return builder == Builder::Sbvh           ? Refs::SpatialSplit
           : builder == Builder::GridBvhSplit ? Refs::Partial
                                              : Refs::Once;
}

TEST(TreeletRestructuring, KeepsInvariantsAndNeverRaisesSah) {
    const Builder builders[] = {Builder::BinnedSah, Builder::SweepSah, Builder::Sbvh,    Builder::Lbvh30,
                                Builder::Hlbvh2,    Builder::Ploc,     Builder::GridBvh, Builder::GridBvhSplit};
    for (const NamedScene& scene : scenes()) {
        for (const Builder builder : builders) {
            for (const int leaf_size : {1, 4}) {
                SCOPED_TRACE(scene.name + " " + to_string(builder) + " leaf size " + std::to_string(leaf_size));
                const BuildOptions options{.builder = builder, .max_leaf_size = leaf_size};
                const std::span<const Triangle> tris = scene.geometry.triangles;
                Bvh bvh = build_bvh(tris, options);
                const double before = bvh.sah_cost();
                optimize_treelets(bvh, tris, bvh_build_config(options), TreeletOptions{.enabled = true});
                EXPECT_LE(bvh.sah_cost(), before);
                check_bvh(bvh, tris, leaf_size, refs_of(builder));
            }
        }
    }
}

TEST(TreeletRestructuring, LowersSahOfLbvh) {
    const SceneGeometry soup = test::make_triangle_soup(5000, 41, {Vec3f(-20.0f), Vec3f(20.0f)}, 0.8f);
    const BuildOptions lbvh{.builder = Builder::Lbvh30};
    const Bvh original = build_bvh(soup.triangles, lbvh);
    double previous = original.sah_cost();
    for (const int rounds : {1, 3}) {
        Bvh bvh = original;
        optimize_treelets(bvh, soup.triangles, bvh_build_config(lbvh), TreeletOptions{.enabled = true, .rounds = rounds});
        const double after = bvh.sah_cost();
        EXPECT_LT(after, original.sah_cost() * 0.97) << original.sah_cost() << " -> " << after;
        EXPECT_LE(after, previous) << "more rounds did worse";
        previous = after;
        check_bvh(bvh, soup.triangles, 4);
    }
    // Smaller treelets gain less, but still gain.
    Bvh small = original;
    optimize_treelets(small, soup.triangles, bvh_build_config(lbvh), TreeletOptions{.enabled = true, .treelet_leaves = 3});
    EXPECT_LT(small.sah_cost(), original.sah_cost());
    check_bvh(small, soup.triangles, 4);
}

TEST(TreeletRestructuring, ClosestHitsEqualBruteForce) {
    for (const NamedScene& scene : scenes()) {
        for (const Builder builder : {Builder::Lbvh30, Builder::BinnedSah, Builder::Sbvh}) {
            SCOPED_TRACE(scene.name + " " + to_string(builder));
            BuildOptions options{.builder = builder, .layout = Layout::Bvh2, .max_leaf_size = 2};
            options.treelets.enabled = true;
            const auto accel = build_accel(scene.geometry, options);
            const BruteForceAccel brute(scene.geometry);
            for (const Ray& ray : test::make_rays(scene.geometry, 800, 5)) {
                const Hit expected = brute.intersect(ray);
                const Hit got = accel->intersect(ray);
                ASSERT_EQ(got.found(), expected.found());
                EXPECT_EQ(accel->occluded(ray), expected.found());
                if (!expected.found()) continue;
                if (got.prim != expected.prim) {  // another triangle at (almost) the same distance
                    EXPECT_NEAR(got.t, expected.t, 1e-5f * std::fabs(expected.t));
                } else {
                    EXPECT_EQ(got.t, expected.t);
                }
            }
        }
    }
}

TEST(TreeletRestructuring, SameTreeForAnyThreadCount) {
    const SceneGeometry soup = test::make_triangle_soup(20000, 5, {Vec3f(-30.0f), Vec3f(30.0f)}, 0.6f);
    for (const Builder builder : {Builder::Lbvh30, Builder::Ploc}) {
        BuildOptions options{.builder = builder};
        options.treelets.enabled = true;
        options.threads = 1;
        const Bvh one = build_bvh(soup.triangles, options);
        options.threads = 0;
        const Bvh all = build_bvh(soup.triangles, options);
        EXPECT_TRUE(identical(one, all)) << to_string(builder);
    }
}

// One leaf walk at a time: the second arrival is the one that goes on.
struct SerialArrival {
    static uint32_t arrive(uint32_t* counter) { return (*counter)++; }
};

// The CPU pass's steps replayed serially, leaf walks in a shuffled order;
// returns the final raw child pairs.
std::vector<uint32_t> replay(const Bvh& bvh, const BvhBuildConfig& config, const TreeletOptions& options,
                             uint32_t seed) {
    const size_t n = bvh.nodes.size();
    std::vector<uint32_t> children(2 * n), parents(n), counts(n), arrivals(n), raw(2 * n);
    std::vector<Box3f> boxes(n);
    std::vector<float> costs(n);
    treelet::TreeView view{bvh.nodes.data(), children.data(), parents.data(), boxes.data(),
                           counts.data(),    costs.data(),    arrivals.data(), treelet::emit_costs(config),
                           0u,               options.treelet_leaves};
    std::vector<uint32_t> leaves;
    for (uint32_t i = 0; i < n; ++i) {
        treelet::init_node(view, i);
        if (bvh.nodes[i].is_leaf()) leaves.push_back(i);
    }
    std::mt19937 rng(seed);
    for (int round = 0; round < options.rounds; ++round) {
        view.gamma = treelet::round_gamma(options, round);
        std::shuffle(leaves.begin(), leaves.end(), rng);
        for (const uint32_t leaf : leaves) treelet::restructure_from_leaf<SerialArrival>(view, leaf);
        EXPECT_TRUE(std::all_of(arrivals.begin(), arrivals.end(), [](uint32_t a) { return a == 0; }));
    }
    for (uint32_t i = 0; i < n; ++i) treelet::raw_children(view, i, raw.data());
    return raw;
}

TEST(TreeletRestructuring, StepsGiveTheSameTreeInAnyOrder) {
    const SceneGeometry soup = test::make_triangle_soup(4000, 17, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    const BuildOptions options{.builder = Builder::Lbvh30};
    const BvhBuildConfig config = bvh_build_config(options);
    const Bvh input = build_bvh(soup.triangles, options);
    const TreeletOptions treelets{.enabled = true};
    const std::vector<uint32_t> first = replay(input, config, treelets, 1);
    EXPECT_EQ(replay(input, config, treelets, 2), first);
    EXPECT_EQ(replay(input, config, treelets, 3), first);
    // And the pass itself (parallel walks) emits the replay's tree.
    Bvh expected = input;
    treelet::keep_if_not_worse(expected, treelet::emit_restructured(input, soup.triangles, config, first), config.sah);
    Bvh pass = input;
    optimize_treelets(pass, soup.triangles, config, treelets);
    EXPECT_TRUE(identical(pass, expected));
    EXPECT_LT(pass.sah_cost(), input.sah_cost());
}

TEST(TreeletRestructuring, EveryTreeletSizeAndRoundCount) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    const BuildOptions options{.builder = Builder::Hlbvh2, .max_leaf_size = 3};
    const Bvh input = build_bvh(sphere.triangles, options);
    for (int leaves = treelet::kMinLeaves; leaves <= treelet::kMaxLeaves; ++leaves) {
        for (const int rounds : {1, 2, 5}) {
            SCOPED_TRACE(std::to_string(leaves) + " leaves, " + std::to_string(rounds) + " rounds");
            Bvh bvh = input;
            optimize_treelets(bvh, sphere.triangles, bvh_build_config(options),
                              TreeletOptions{.enabled = true, .treelet_leaves = leaves, .rounds = rounds});
            EXPECT_LE(bvh.sah_cost(), input.sah_cost());
            check_bvh(bvh, sphere.triangles, 3);
        }
    }
}

// Trees at the depth limit (a Morton chain of 63 levels; exponentially
// spaced triangles): whatever the treelets do, the emitter keeps depth <= 64.
TEST(TreeletRestructuring, DeepTreesStayWithinTheDepthLimit) {
    SceneGeometry row;
    float x = 1.0f;
    for (int i = 0; i < 900; ++i, x *= 1.09f) test::append(row, {Vec3f(x, 0, 0), Vec3f(x, 1, 0), Vec3f(x, 0, 1)});
    SceneGeometry chain = test::make_morton_chain(300);
    for (const SceneGeometry* scene : {&row, &chain}) {
        for (const Builder builder : {Builder::Lbvh63, Builder::BinnedSah}) {
            SCOPED_TRACE(to_string(builder));
            const BuildOptions options{.builder = builder, .max_leaf_size = 1};
            Bvh bvh = build_bvh(scene->triangles, options);
            const double before = bvh.sah_cost();
            optimize_treelets(bvh, scene->triangles, bvh_build_config(options), TreeletOptions{.enabled = true});
            EXPECT_LE(bvh.sah_cost(), before);
            check_bvh(bvh, scene->triangles, 1);
        }
    }
}

TEST(TreeletRestructuring, SmallAndEmptyTrees) {
    for (const size_t count : {size_t{0}, size_t{1}, size_t{2}, size_t{3}, size_t{9}}) {
        const SceneGeometry soup = test::make_triangle_soup(count, 3, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.3f);
        const BuildOptions options{.builder = Builder::BinnedSah, .max_leaf_size = 1};
        Bvh bvh = build_bvh(soup.triangles, options);
        const double before = bvh.nodes.empty() ? 0.0 : bvh.sah_cost();
        optimize_treelets(bvh, soup.triangles, bvh_build_config(options), TreeletOptions{.enabled = true});
        if (count > 0) EXPECT_LE(bvh.sah_cost(), before);
        check_bvh(bvh, soup.triangles, 1);
    }
}

TEST(TreeletRestructuring, RejectsBadInput) {
    const SceneGeometry soup = test::make_triangle_soup(100, 3, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.3f);
    const BuildOptions options{.builder = Builder::BinnedSah};
    const BvhBuildConfig config = bvh_build_config(options);
    const Bvh bvh = build_bvh(soup.triangles, options);
    for (const TreeletOptions bad : {TreeletOptions{.enabled = true, .treelet_leaves = 2},
                                     TreeletOptions{.enabled = true, .treelet_leaves = 8},
                                     TreeletOptions{.enabled = true, .rounds = 0}}) {
        Bvh copy = bvh;
        EXPECT_THROW(optimize_treelets(copy, soup.triangles, config, bad), Error);
    }
    Bvh too_few = bvh;  // primitive indices past the triangles
    EXPECT_THROW(optimize_treelets(too_few, std::span(soup.triangles).first(50), config, TreeletOptions{}), Error);
    BuildOptions invalid = options;
    invalid.treelets = {.enabled = true, .rounds = 40};
    EXPECT_THROW(build_bvh(soup.triangles, invalid), Error);
}

}  // namespace
}  // namespace rf
