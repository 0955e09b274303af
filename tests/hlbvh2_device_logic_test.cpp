// The per-thread logic of the CUDA HLBVH2 (Garanzha 2014 ch. 5; src/accel/bvh/
// builders/hlbvh2_bottom_steps.h) run on the CPU the way the kernels run it.
// The bottom trees' one launch: a thread per split position (node_of_split,
// build_split_node) and one per cluster root, in shuffled orders. Checks the
// forest against an independent top-down reference (every slot, so the same
// node indices and children; unused slots untouched), on scenes and on
// random codes with long runs of equal codes and leaf sizes up to 255, that
// every primitive is in exactly one leaf, that the parent links invert the
// references, and that the host emission (emit_hlbvh2_forest, the device
// build's host half) gives build_hlbvh2's BVH. A moved split and a lost
// thread must fail. The one-launch box passes (boxes_from_leaf over the
// bottom trees, top_boxes_from_node over the top level) run their walks in
// shuffled orders with arrival counters and must give the level-wise pass's
// boxes bit for bit (signed zeros included); a walk that goes on at the
// first arrival must fail.
// The top level (hlbvh2_top_steps.h; backend/cuda/hlbvh2_top_level.cu) is run
// the same way: one launch per level, 4 tasks per warp, 8 lanes per task
// whose shuffles (butterfly bounds, prefix/suffix bin scans, the candidate
// fold) and ballots (the stable partition, the enqueue) are emulated lane by
// lane, warps shuffled; its references must be the CPU's top level
// (build_hlbvh2_top_level) and, emitted, give build_hlbvh2's BVH. A wrong
// tie rule must fail. Large tasks take the block path (one block per task:
// strided binning by shared-memory atomics on ordered float keys, emulated
// in shuffled thread orders; the partition by a block scan); its merged bins
// must equal bin_task's, its tree the CPU's, and a wrong stride must fail.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/hlbvh2_emit.h"
#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "accel/bvh/builders/hlbvh2_top_steps.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel_test_scenes.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using hlbvh2::kLeafRef;

constexpr uint32_t kUnset = 0xdeadbeefu;
constexpr uint32_t kWarp = 32;

bool same_box(const Box3f& a, const Box3f& b) { return std::memcmp(&a, &b, sizeof(Box3f)) == 0; }

// What the device has after the sort and the cluster compaction.
struct SortedClusters {
    std::vector<uint32_t> keys, order;
    std::vector<Box3f> triangle_boxes;  // per triangle
    std::vector<uint32_t> cluster_begin, cluster_prefix;
};

SortedClusters sort_and_cluster(std::span<const Triangle> triangles) {
    morton::RawTree tree(triangles, BvhBuildConfig{});
    morton::Buffer<uint32_t> keys;
    tree.sort_by_morton_codes(keys);
    SortedClusters s;
    const uint32_t n = tree.size();
    s.keys.assign(keys.data(), keys.data() + n);
    s.order = tree.order;
    s.triangle_boxes.resize(n);
    for (uint32_t i = 0; i < n; ++i) s.triangle_boxes[s.order[i]] = tree.boxes[i];
    for (uint32_t i = 0; i < n; ++i) {
        if (i == 0 || (s.keys[i] >> hlbvh2::kClusterShift) != (s.keys[i - 1] >> hlbvh2::kClusterShift)) {
            s.cluster_begin.push_back(i);
            s.cluster_prefix.push_back(s.keys[i] >> hlbvh2::kClusterShift);
        }
    }
    s.cluster_begin.push_back(n);
    return s;
}

// One split thread of the bottom trees' launch with its node's split moved
// one position right where possible: the bug the checks must catch.
void build_split_node_wrong(const uint32_t* codes, uint32_t n, uint32_t i, uint32_t leaf_size,
                            const hlbvh2::BottomTrees& out) {
    uint32_t first = 0, end = 0;
    if (!hlbvh2::node_of_split(codes, n, i, leaf_size, &first, &end)) return;
    const uint32_t mid = i + 2 < end ? i + 2 : i + 1;
    out.refs[2 * i] = hlbvh2::subtree_reference(codes, first, mid, leaf_size, i, out);
    out.refs[2 * i + 1] = hlbvh2::subtree_reference(codes, mid, end, leaf_size, i, out);
}

using SplitThread = void (*)(const uint32_t*, uint32_t, uint32_t, uint32_t, const hlbvh2::BottomTrees&);

struct BottomForest {
    std::vector<uint32_t> refs;
    std::vector<uint8_t> leaf_runs;
    std::vector<uint32_t> inner_parent, leaf_parent;
    [[nodiscard]] hlbvh2::BottomTrees view() {
        return {refs.data(), leaf_runs.data(), inner_parent.data(), leaf_parent.data()};
    }
};

// The bottom trees' launch (hlbvh2_build.cu bottom_trees_kernel): n - 1
// split threads, then one per cluster, run in a shuffled order (each
// writes only its own node's slots). `lost`: a split thread that never
// runs (a bug to catch), none by default.
BottomForest run_bottom_launch(const SortedClusters& s, uint32_t leaf_size, uint32_t seed,
                               SplitThread split = hlbvh2::build_split_node, uint32_t lost = kUnset) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const uint32_t clusters = static_cast<uint32_t>(s.cluster_prefix.size());
    BottomForest f;
    f.refs.assign(2 * size_t{n - 1} + clusters, kUnset);
    f.leaf_runs.assign(n, 0);
    f.inner_parent.assign(n - 1, kUnset);
    f.leaf_parent.assign(n, hlbvh2::kNoParent);  // the device's memset
    const hlbvh2::BottomTrees out = f.view();
    std::vector<uint32_t> threads(n - 1 + clusters);
    std::iota(threads.begin(), threads.end(), 0u);
    std::shuffle(threads.begin(), threads.end(), std::mt19937(seed));
    for (uint32_t t : threads) {
        if (t < n - 1) {
            if (t != lost) split(s.keys.data(), n, t, leaf_size, out);
        } else {
            const uint32_t c = t - (n - 1);
            hlbvh2::build_cluster_root(s.keys.data(), n, c, s.cluster_begin[c], s.cluster_begin[c + 1], leaf_size,
                                       out);
        }
    }
    return f;
}

// Thread orders of the box pass: which walk reaches a node second is up to
// the hardware.
std::vector<uint32_t> shuffled(uint32_t count, uint32_t seed) {
    std::vector<uint32_t> order(count);
    std::iota(order.begin(), order.end(), 0u);
    std::shuffle(order.begin(), order.end(), std::mt19937(seed));
    return order;
}

// The bottom boxes' launch (hlbvh2_build.cu bottom_boxes_kernel): one walk
// per sorted position, in a shuffled order, inner boxes poisoned before.
template <class Arrival>
void run_bottom_box_pass(const SortedClusters& s, const BottomForest& f, uint32_t seed, std::vector<Box3f>& inner_boxes,
                         std::vector<Box3f>& cluster_boxes) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    Box3f poison;
    poison.lo = Vec3f(1e30f);
    poison.hi = Vec3f(-1e30f);
    inner_boxes.assign(n - 1, poison);
    cluster_boxes.assign(s.cluster_prefix.size(), poison);
    std::vector<uint32_t> arrivals(n - 1, 0);
    const hlbvh2::BottomBoxPass pass{{f.refs.data(), f.leaf_runs.data(), s.order.data(), s.triangle_boxes.data(),
                                      inner_boxes.data()},
                                     f.inner_parent.data(), f.leaf_parent.data(), arrivals.data(),
                                     cluster_boxes.data()};
    for (uint32_t position : shuffled(n, seed)) hlbvh2::boxes_from_leaf<Arrival>(pass, position);
}

// The level-wise pass the one-launch pass replaces, as a recursion: each
// inner node's box union(left, right), a leaf's its run's fold.
Box3f expected_box(const hlbvh2::BoxView& v, uint32_t ref, std::vector<Box3f>& inner_boxes) {
    if ((ref & kLeafRef) != 0) return hlbvh2::reference_box(v, ref);
    const Box3f left = expected_box(v, v.refs[2 * ref], inner_boxes);
    const Box3f right = expected_box(v, v.refs[2 * ref + 1], inner_boxes);
    return inner_boxes[ref] = hlbvh2::box_union(left, right);
}

// A walk that goes on at the first arrival: its sibling may not be final (a bug to catch).
struct FirstArrivalContinues {
    static uint32_t arrive(uint32_t* counter) { return (*counter)++ == 0 ? 1u : 0u; }
};

// Independent reference: the bottom trees top-down, the split found by a
// linear scan for the first code with the highest differing bit set.
void reference_range(const std::vector<uint32_t>& keys, uint32_t a, uint32_t b, uint32_t slot, uint32_t leaf_size,
                     std::vector<uint32_t>& refs) {
    if (b - a <= leaf_size) {
        refs[slot] = kLeafRef | a;
        return;
    }
    uint32_t mid = a + (b - a) / 2;
    const uint32_t differ = keys[a] ^ keys[b - 1];
    if (differ != 0) {
        const int bit = std::bit_width(differ) - 1;
        mid = a;
        while (((keys[mid] >> bit) & 1u) == 0) ++mid;
    }
    refs[slot] = mid - 1;
    reference_range(keys, a, mid, 2 * (mid - 1), leaf_size, refs);
    reference_range(keys, mid, b, 2 * (mid - 1) + 1, leaf_size, refs);
}

// Walks the forest from the cluster roots; counts how often each primitive
// is reached through a leaf, and compares every reached slot with `expected`.
void walk(const std::vector<uint32_t>& refs, const std::vector<uint8_t>& leaf_runs, const std::vector<uint32_t>& expected,
          uint32_t ref, std::vector<uint32_t>& seen, size_t& wrong) {
    if (ref & kLeafRef) {
        const uint32_t first = ref & ~kLeafRef;
        for (uint32_t i = 0; i < leaf_runs[first]; ++i) ++seen[first + i];
        return;
    }
    for (int side = 0; side < 2; ++side) {
        const uint32_t slot = 2 * ref + side;
        wrong += refs[slot] != expected[slot];
        walk(refs, leaf_runs, expected, refs[slot], seen, wrong);
    }
}

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> scenes() {
    std::vector<NamedScene> out;
    out.push_back({"soup", test::make_triangle_soup(20000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    out.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    out.push_back({"nasty", test::make_nasty_geometry(2)});
    SceneGeometry point;  // every triangle in one point: all codes equal, one cluster
    for (int i = 0; i < 1000; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    out.push_back({"one point", std::move(point)});
    SceneGeometry lattice;  // 4^3 tiny triangles on a lattice: every cluster one triangle
    for (int x = 0; x < 4; ++x) {
        for (int y = 0; y < 4; ++y) {
            for (int z = 0; z < 4; ++z) {
                const Vec3f p{static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
                test::append(lattice, {p, p + Vec3f(0.01f, 0, 0), p + Vec3f(0, 0.01f, 0)});
            }
        }
    }
    out.push_back({"singleton clusters", std::move(lattice)});
    SceneGeometry two;
    test::append(two, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    test::append(two, {Vec3f(0, 0, 2), Vec3f(1, 0, 2), Vec3f(0, 1, 2)});
    out.push_back({"two", std::move(two)});
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    out.push_back({"one", std::move(one)});
    return out;
}

Hlbvh2Forest to_forest(const SortedClusters& s, const BottomForest& f, std::vector<uint32_t> top_refs = {}) {
    return {s.order, f.refs, s.cluster_begin, s.cluster_prefix, std::move(top_refs)};
}

bool same_bvh(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() && a.prim_indices == b.prim_indices &&
           (a.nodes.empty() || std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(a.nodes[0])) == 0);
}

// The reference forest over every cluster (kUnset where no node is).
std::vector<uint32_t> reference_forest(const SortedClusters& s, uint32_t leaf_size) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const uint32_t clusters = static_cast<uint32_t>(s.cluster_prefix.size());
    std::vector<uint32_t> expected(2 * size_t{n - 1} + clusters, kUnset);
    for (uint32_t c = 0; c < clusters; ++c) {
        reference_range(s.keys, s.cluster_begin[c], s.cluster_begin[c + 1], 2 * (n - 1) + c, leaf_size, expected);
    }
    return expected;
}

// The launch's forest against the reference: every slot (unused ones
// untouched), each primitive in one leaf, and parent links that invert the
// child references.
void expect_reference_forest(const SortedClusters& s, const BottomForest& f, uint32_t leaf_size) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const uint32_t clusters = static_cast<uint32_t>(s.cluster_prefix.size());
    const std::vector<uint32_t> expected = reference_forest(s, leaf_size);
    EXPECT_EQ(f.refs, expected);
    std::vector<uint32_t> seen(n, 0);
    size_t wrong = 0;
    for (uint32_t c = 0; c < clusters; ++c) walk(f.refs, f.leaf_runs, expected, f.refs[2 * (n - 1) + c], seen, wrong);
    EXPECT_EQ(wrong, 0u);
    EXPECT_EQ(std::count(seen.begin(), seen.end(), 1u), static_cast<long>(n)) << "primitives not in exactly one leaf";
    size_t bad_links = 0, leaves = 0;
    auto parent_of = [&](uint32_t ref) {
        return (ref & kLeafRef) != 0 ? f.leaf_parent[ref & ~kLeafRef] : f.inner_parent[ref];
    };
    for (uint32_t c = 0; c < clusters; ++c) bad_links += parent_of(f.refs[2 * (n - 1) + c]) != (hlbvh2::kClusterRootOf | c);
    for (uint32_t i = 0; i + 1 < n; ++i) {
        if (expected[2 * i] == kUnset) continue;
        for (int side = 0; side < 2; ++side) bad_links += parent_of(f.refs[2 * i + side]) != i;
    }
    for (uint32_t p : f.leaf_parent) leaves += p != hlbvh2::kNoParent;
    EXPECT_EQ(bad_links, 0u);
    EXPECT_EQ(leaves, static_cast<size_t>(std::count_if(expected.begin(), expected.end(), [](uint32_t r) {
                  return r != kUnset && (r & kLeafRef) != 0;
              })));
}

// Sorted codes as the device sees them, without triangles (order and
// boxes left empty): for the bottom trees' structure alone.
SortedClusters clusters_of_codes(std::vector<uint32_t> keys) {
    std::sort(keys.begin(), keys.end());
    SortedClusters s;
    s.keys = std::move(keys);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    for (uint32_t i = 0; i < n; ++i) {
        if (i == 0 || (s.keys[i] >> hlbvh2::kClusterShift) != (s.keys[i - 1] >> hlbvh2::kClusterShift)) {
            s.cluster_begin.push_back(i);
            s.cluster_prefix.push_back(s.keys[i] >> hlbvh2::kClusterShift);
        }
    }
    s.cluster_begin.push_back(n);
    return s;
}

TEST(Hlbvh2DeviceLogic, OneLaunchBuildsTheCpuBottomTrees) {
    for (const NamedScene& scene : scenes()) {
        if (scene.geometry.triangles.size() < 2) continue;  // the host builds those
        for (uint32_t leaf_size : {1u, 4u}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            for (uint32_t seed : {1u, 2u}) expect_reference_forest(s, run_bottom_launch(s, leaf_size, seed), leaf_size);
        }
    }
}

// Codes with long runs of equal values, clusters of every size, and leaf
// sizes up to 255: the halvings of runs and the radix ranges around them.
TEST(Hlbvh2DeviceLogic, OneLaunchOnCodesWithRuns) {
    std::mt19937 rng(17);
    for (int round = 0; round < 60; ++round) {
        const uint32_t n = 2 + rng() % 3000;
        const uint32_t distinct = 1 + rng() % (round % 3 == 0 ? 4 : 400);
        const uint32_t clusters = 1 + rng() % 6;
        std::vector<uint32_t> values(distinct);
        for (uint32_t& v : values) v = ((rng() % clusters) << hlbvh2::kClusterShift) | (rng() & ((1u << 15) - 1));
        std::vector<uint32_t> keys(n);
        for (uint32_t& k : keys) k = values[rng() % distinct] & ((1u << hlbvh2::kCodeBits) - 1);
        const SortedClusters s = clusters_of_codes(std::move(keys));
        for (uint32_t leaf_size : {1u, 2u, 3u, 8u, 255u}) {
            SCOPED_TRACE("round " + std::to_string(round) + ", leaves of " + std::to_string(leaf_size));
            expect_reference_forest(s, run_bottom_launch(s, leaf_size, static_cast<uint32_t>(round)), leaf_size);
        }
    }
}

TEST(Hlbvh2DeviceLogic, OneLaunchBoxesAreTheLevelWiseBoxes) {
    std::vector<NamedScene> all = scenes();
    SceneGeometry zeros;  // bounds of both signs of zero: the union's order shows
    std::mt19937 rng(3);
    for (int i = 0; i < 400; ++i) {
        const float x = (rng() & 1) ? -0.0f : 0.0f, y = static_cast<float>(rng() % 7), z = (rng() & 1) ? -0.0f : 0.0f;
        test::append(zeros, {Vec3f(x, y, z), Vec3f(z, y + 1.0f, x), Vec3f(x, y, 1.0f)});
    }
    all.push_back({"signed zeros", std::move(zeros)});
    for (const NamedScene& scene : all) {
        if (scene.geometry.triangles.size() < 2) continue;
        for (uint32_t leaf_size : {1u, 4u}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            const BottomForest f = run_bottom_launch(s, leaf_size, 5);
            const uint32_t n = static_cast<uint32_t>(s.keys.size());
            std::vector<Box3f> expected_inner(n - 1);
            const hlbvh2::BoxView expected_view{f.refs.data(), f.leaf_runs.data(), s.order.data(),
                                                s.triangle_boxes.data(), expected_inner.data()};
            std::vector<Box3f> expected_clusters;
            for (size_t c = 0; c < s.cluster_prefix.size(); ++c) {
                expected_clusters.push_back(expected_box(expected_view, f.refs[2 * (n - 1) + c], expected_inner));
            }
            for (uint32_t seed : {1u, 2u, 3u}) {
                std::vector<Box3f> inner, cluster_boxes;
                run_bottom_box_pass<karras::AtomicArrival>(s, f, seed, inner, cluster_boxes);
                size_t wrong = 0;
                for (uint32_t i = 0; i + 1 < n; ++i) wrong += f.inner_parent[i] != kUnset && !same_box(inner[i], expected_inner[i]);
                for (size_t c = 0; c < cluster_boxes.size(); ++c) wrong += !same_box(cluster_boxes[c], expected_clusters[c]);
                EXPECT_EQ(wrong, 0u) << "seed " << seed;
            }
        }
    }
}

TEST(Hlbvh2DeviceLogic, FirstArrivalContinuingIsCaught) {
    const SortedClusters s = sort_and_cluster(test::make_triangle_soup(5000, 3, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.1f).triangles);
    const BottomForest f = run_bottom_launch(s, 1, 1);
    std::vector<Box3f> good_inner, good_clusters, bad_inner, bad_clusters;
    run_bottom_box_pass<karras::AtomicArrival>(s, f, 4, good_inner, good_clusters);
    run_bottom_box_pass<FirstArrivalContinues>(s, f, 4, bad_inner, bad_clusters);
    size_t differ = 0;
    for (size_t c = 0; c < good_clusters.size(); ++c) differ += !same_box(good_clusters[c], bad_clusters[c]);
    EXPECT_GT(differ, 0u);
}

TEST(Hlbvh2DeviceLogic, HostEmissionIsBuildHlbvh2) {
    for (const NamedScene& scene : scenes()) {
        if (scene.geometry.triangles.size() < 2) continue;
        for (int leaf_size : {1, 4, 8}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const BvhBuildConfig config{.max_leaf_size = leaf_size};
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            const BottomForest f = run_bottom_launch(s, static_cast<uint32_t>(leaf_size), 11);
            Hlbvh2Stages stages;
            const Bvh got = emit_hlbvh2_forest(scene.geometry.triangles, config, to_forest(s, f), &stages);
            EXPECT_TRUE(same_bvh(build_hlbvh2(scene.geometry.triangles, config), got));
        }
    }
    EXPECT_TRUE(emit_hlbvh2_forest({}, {}, Hlbvh2Forest{}).nodes.empty());
}

// The top level's records on the device: a level that fits opens the next
// one after its entries; one that overflows its queues or the node list
// (or follows a fault) runs nothing and faults the next, whose counts stay
// 0, which ends the host's loop.
TEST(Hlbvh2DeviceLogic, LevelRecordsFaultInsteadOfOverrunning) {
    const hlbvh2::TopQueueCapacity capacity{4, 2, 10};
    hlbvh2::TopQueueLevel top_next{};
    EXPECT_TRUE(hlbvh2::open_next_top_level({0, 4, 2, 4, 0}, &top_next, capacity));
    EXPECT_EQ(top_next.base, 10u);
    EXPECT_FALSE(hlbvh2::open_next_top_level({0, 5, 0, 0, 0}, &top_next, capacity));
    EXPECT_FALSE(hlbvh2::open_next_top_level({0, 1, 3, 0, 0}, &top_next, capacity));
    EXPECT_FALSE(hlbvh2::open_next_top_level({0, 4, 2, 5, 0}, &top_next, capacity));
    EXPECT_EQ(top_next.fault, 1u);
}

TEST(Hlbvh2DeviceLogic, EnqueueOffsetsArePrefixSums) {
    std::mt19937 rng(5);
    for (int round = 0; round < 100; ++round) {
        uint32_t counts[kWarp], one_or_more = 0, two = 0, sum = 0;
        for (uint32_t lane = 0; lane < kWarp; ++lane) {
            counts[lane] = rng() % 3;
            one_or_more |= (counts[lane] >= 1 ? 1u : 0u) << lane;
            two |= (counts[lane] == 2 ? 1u : 0u) << lane;
        }
        for (uint32_t lane = 0; lane < kWarp; ++lane) {
            ASSERT_EQ(hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(lane)), sum);
            sum += counts[lane];
        }
        ASSERT_EQ(hlbvh2::enqueue_total(one_or_more, two), sum);
    }
}

TEST(Hlbvh2DeviceLogic, WrongSplitIsCaught) {
    const SceneGeometry g = test::make_triangle_soup(3000, 9, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f);
    const BvhBuildConfig config{.max_leaf_size = 1};
    const SortedClusters s = sort_and_cluster(g.triangles);
    const BottomForest f = run_bottom_launch(s, 1, 3, build_split_node_wrong);
    EXPECT_NE(f.refs, reference_forest(s, 1));
    bool same = false;  // a moved split gives another BVH, or a forest the host's check rejects
    try {
        same = same_bvh(build_hlbvh2(g.triangles, config), emit_hlbvh2_forest(g.triangles, config, to_forest(s, f)));
    } catch (const Error&) {
    }
    EXPECT_FALSE(same);
}

TEST(Hlbvh2DeviceLogic, LostSplitThreadIsCaught) {
    const SortedClusters s = sort_and_cluster(test::make_triangle_soup(3000, 9, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f).triangles);
    const std::vector<uint32_t> expected = reference_forest(s, 1);
    uint32_t some_node = 0;
    while (expected[2 * some_node] == kUnset) ++some_node;
    EXPECT_NE(run_bottom_launch(s, 1, 3, hlbvh2::build_split_node, some_node).refs, expected);
}

TEST(Hlbvh2DeviceLogic, MalformedForestThrows) {
    const SceneGeometry g = test::make_triangle_soup(500, 4, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.2f);
    const SortedClusters s = sort_and_cluster(g.triangles);
    const BottomForest f = run_bottom_launch(s, 1, 1);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    Hlbvh2Forest bad = to_forest(s, f);
    // A cluster root pointing at a leaf that is not its range's start.
    bad.refs[2 * (n - 1)] = kLeafRef | 1u;
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, BvhBuildConfig{.max_leaf_size = 1}, std::move(bad)), Error);
}

// ---- The top level ----

using hlbvh2::TopBin;
using hlbvh2::TopCluster;
using hlbvh2::TopTask;
constexpr uint32_t kLanes = hlbvh2::kTopLanes;
constexpr uint32_t kTasksPerWarp = kWarp / kLanes;

// The tie rule the checks must catch: a later candidate of equal cost wins.
bool consider_last_of_equals(hlbvh2::TopSplit& best, float cost, int axis, uint32_t plane) {
    if (best.axis >= 0 && !(cost <= best.cost)) return false;
    best = {cost, axis, plane};
    return true;
}
using Consider = bool (*)(hlbvh2::TopSplit&, float, int, uint32_t);

// choose_split_lanes of hlbvh2_top_level.cu, its 8 lanes in lockstep
// (bins[lane][axis]: lane's bin of each axis; the lanes' bounds are equal).
hlbvh2::TopSplit emulate_split_lanes(const TopBin bins[kLanes][3], const hlbvh2::CellBounds& bounds, uint32_t count,
                                     Consider consider, uint32_t* left_count_out) {
    float cost[kLanes][3] = {};
    bool valid[kLanes][3] = {};
    uint32_t left_clusters[kLanes][3] = {};
    for (int axis = 0; axis < 3; ++axis) {
        TopBin below[kLanes], above[kLanes];
        for (uint32_t lane = 0; lane < kLanes; ++lane) below[lane] = above[lane] = bins[lane][axis];
        for (uint32_t d = 1; d < kLanes; d *= 2) {  // __shfl_up_sync / __shfl_down_sync scans
            TopBin next_below[kLanes], next_above[kLanes];
            for (uint32_t lane = 0; lane < kLanes; ++lane) {
                next_below[lane] = lane >= d ? hlbvh2::merge_bins(below[lane - d], below[lane]) : below[lane];
                next_above[lane] = lane + d < kLanes ? hlbvh2::merge_bins(above[lane], above[lane + d]) : above[lane];
            }
            std::copy(next_below, next_below + kLanes, below);
            std::copy(next_above, next_above + kLanes, above);
        }
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            const TopBin left = lane == 0 ? TopBin{} : below[lane - 1];
            valid[lane][axis] = lane >= 1 && lane < hlbvh2::axis_bins(bounds, axis) &&
                                hlbvh2::plane_cost(left, above[lane], &cost[lane][axis]);
            left_clusters[lane][axis] = left.clusters;
        }
    }
    hlbvh2::TopSplit split;  // every lane folds the same candidates: lane 0's fold stands for all
    uint32_t left_count = count / 2;
    for (int axis = 0; axis < 3; ++axis) {
        for (uint32_t plane = 1; plane < kLanes; ++plane) {
            if (valid[plane][axis] && consider(split, cost[plane][axis], axis, plane)) {
                left_count = left_clusters[plane][axis];
            }
        }
    }
    *left_count_out = left_count;
    return split;
}

// process_top_task of hlbvh2_top_level.cu, its 8 lanes in lockstep: each
// shuffle reads the other lanes' values from before the step.
enum class ScatterBug { None, KeepSent };

// strided_bins_lanes of hlbvh2_top_level.cu, its 8 lanes in lockstep: each
// bins every 8th cluster, then per xor step every lane's sent bins are read
// (the shuffle) before any lane merges them into its kept ones.
void strided_bins_lanes(const TopCluster* in, const TopTask& task, const hlbvh2::CellBounds& bounds,
                        TopBin out[kLanes][3], ScatterBug bug = ScatterBug::None) {
    std::vector<std::array<std::array<TopBin, hlbvh2::kTopBins>, 3>> all(kLanes);
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        TopBin lane_bins[3][hlbvh2::kTopBins];
        hlbvh2::strided_bins_lane(in, task.first, task.end, bounds, lane, lane_bins);
        for (int axis = 0; axis < 3; ++axis) std::copy(lane_bins[axis], lane_bins[axis] + hlbvh2::kTopBins, all[lane][axis].begin());
    }
    for (uint32_t d = kLanes / 2; d > 0; d /= 2) {
        for (uint32_t j = 0; j < d; ++j) {
            TopBin sent[kLanes][3];
            for (uint32_t lane = 0; lane < kLanes; ++lane) {
                const uint32_t k = hlbvh2::scatter_pair(lane, d, j);
                for (int axis = 0; axis < 3; ++axis) sent[lane][axis] = all[lane][axis][hlbvh2::scatter_sent(lane, d, k)];
            }
            for (uint32_t lane = 0; lane < kLanes; ++lane) {
                const uint32_t k = hlbvh2::scatter_pair(lane, d, j);
                const uint32_t kept = bug == ScatterBug::KeepSent ? hlbvh2::scatter_sent(lane, d, k)
                                                                  : hlbvh2::scatter_kept(lane, d, k);
                for (int axis = 0; axis < 3; ++axis) {
                    all[lane][axis][kept] = hlbvh2::merge_bins(all[lane][axis][kept], sent[lane ^ d][axis]);
                }
            }
        }
    }
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        for (int axis = 0; axis < 3; ++axis) out[lane][axis] = all[lane][axis][lane];
    }
}

uint32_t emulate_top_task(const TopTask& task, const TopCluster* in, TopCluster* out, uint32_t top_base,
                          uint32_t* top_refs, TopTask children[2], Consider consider) {
    const uint32_t count = task.end - task.first;
    hlbvh2::CellBounds bounds[kLanes];
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        bounds[lane] = hlbvh2::strided_cell_bounds(in, task.first, task.end, lane, kLanes);
    }
    for (uint32_t d = kLanes / 2; d > 0; d /= 2) {  // __shfl_xor_sync butterfly
        hlbvh2::CellBounds next[kLanes];
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            next[lane] = bounds[lane];
            hlbvh2::merge(next[lane], bounds[lane ^ d]);
        }
        std::copy(next, next + kLanes, bounds);
    }
    TopBin bins[kLanes][3];
    if (count > hlbvh2::kTopStridedBinMin) {
        strided_bins_lanes(in, task, bounds[0], bins);
    } else {
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            hlbvh2::bin_task_lane(in, task.first, task.end, bounds[lane], lane, bins[lane]);
        }
    }
    uint32_t left_count = 0;
    const hlbvh2::TopSplit split = emulate_split_lanes(bins, bounds[0], count, consider, &left_count);
    const uint32_t right_count = count - left_count;
    uint32_t lefts = 0;
    for (uint32_t chunk = task.first; chunk < task.end; chunk += kLanes) {
        bool left[kLanes] = {};
        uint32_t left_bits = 0;  // the ballot
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            const uint32_t i = chunk + lane;
            if (i >= task.end) continue;
            left[lane] = hlbvh2::cluster_goes_left(in[i], i, task, bounds[lane], split, left_count);
            left_bits |= (left[lane] ? 1u : 0u) << lane;
        }
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            const uint32_t i = chunk + lane;
            if (i >= task.end) continue;
            const uint32_t lefts_before = lefts + static_cast<uint32_t>(std::popcount(left_bits & ((1u << lane) - 1u)));
            out[hlbvh2::partition_slot(task, left_count, i, lefts_before, left[lane])] = in[i];
            if (left[lane] && left_count == 1) top_refs[2 * task.node] = in[i].root;
            if (!left[lane] && right_count == 1) top_refs[2 * task.node + 1] = in[i].root;
        }
        lefts += static_cast<uint32_t>(std::popcount(left_bits));
    }
    TopTask halves[2];
    hlbvh2::child_tasks(task, left_count, halves);
    uint32_t inner = 0;
    for (int side = 0; side < 2; ++side) {
        if (halves[side].end - halves[side].first < 2) continue;
        top_refs[2 * task.node + side] = top_base + halves[side].node;
        children[inner++] = halves[side];
    }
    return inner;
}

// The block path (large_task_by_block) emulated: shared-memory atomics as
// plain updates (they commute: any order gives the same words).
constexpr uint32_t kTaskBlock = 256;  // hlbvh2_top_level.cu's kTopTaskBlock
constexpr uint32_t kTaskBlockWarps = kTaskBlock / kWarp;
struct PlainAtomics {
    void min(uint32_t* word, uint32_t value) const { *word = std::min(*word, value); }
    void max(uint32_t* word, uint32_t value) const { *word = std::max(*word, value); }
    void add(uint32_t* word, uint32_t value) const { *word += value; }
};

// Equal as values: zeros of either sign are equal (the only difference the
// key encoding may make, see hlbvh2_top_steps.h).
bool same_bin_value(const TopBin& a, const TopBin& b) {
    return a.box.lo.x == b.box.lo.x && a.box.lo.y == b.box.lo.y && a.box.lo.z == b.box.lo.z &&
           a.box.hi.x == b.box.hi.x && a.box.hi.y == b.box.hi.y && a.box.hi.z == b.box.hi.z &&
           a.triangles == b.triangles && a.clusters == b.clusters;
}

struct BlockPathStats {
    size_t tasks = 0;           // tasks run by the block path
    size_t bin_mismatches = 0;  // merged shared bins unlike bin_task's
    size_t bad_slots = 0;       // partition slots outside the task (skipped: a bug's symptom)
    size_t zero_signs = 0;      // bins equal to bin_task's as values, not as bits
};

// large_task_by_block for one task, its threads in shuffled orders:
// strided cell bounds merged as the shared atomics would, strided binning
// into the warps' key bins, the 8 lanes' merge and split, the partition by
// an exclusive scan per chunk of kTaskBlock clusters. `stride`: the threads'
// stride over the clusters (kTaskBlock; anything else is a bug to catch).
uint32_t emulate_large_top_task(const TopTask& task, const TopCluster* in, TopCluster* out, uint32_t top_base,
                                uint32_t* top_refs, TopTask children[2], Consider consider, uint32_t stride,
                                std::mt19937& rng, BlockPathStats& stats) {
    const uint32_t count = task.end - task.first;
    std::vector<uint32_t> threads(kTaskBlock);
    std::iota(threads.begin(), threads.end(), 0u);
    std::shuffle(threads.begin(), threads.end(), rng);
    hlbvh2::CellBounds bounds = hlbvh2::empty_cell_bounds();
    for (uint32_t t : threads) hlbvh2::merge(bounds, hlbvh2::strided_cell_bounds(in, task.first, task.end, t, stride));
    std::shuffle(threads.begin(), threads.end(), rng);
    hlbvh2::TopBinKeys warp_bins[kTaskBlockWarps][3][hlbvh2::kTopBins];
    for (auto& warp : warp_bins) {
        for (auto& axis : warp) std::fill(axis, axis + hlbvh2::kTopBins, hlbvh2::empty_bin_keys());
    }
    PlainAtomics atomics;
    for (uint32_t t : threads) {
        hlbvh2::strided_bin_keys(in, task.first, task.end, t, stride, bounds, warp_bins[t / kWarp], atomics);
    }
    TopBin bins[kLanes][3];
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        for (int axis = 0; axis < 3; ++axis) {
            hlbvh2::TopBinKeys keys = warp_bins[0][axis][lane];
            for (uint32_t w = 1; w < kTaskBlockWarps; ++w) hlbvh2::merge_keys(keys, warp_bins[w][axis][lane]);
            bins[lane][axis] = hlbvh2::decode_bin(keys);
        }
    }
    TopBin expected[3][hlbvh2::kTopBins];
    hlbvh2::bin_task(in, task.first, task.end, bounds, expected);
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        for (int axis = 0; axis < 3; ++axis) {
            const bool same = same_bin_value(bins[lane][axis], expected[axis][lane]);
            stats.bin_mismatches += !same;
            stats.zero_signs += same && !same_box(bins[lane][axis].box, expected[axis][lane].box);
        }
    }
    ++stats.tasks;
    uint32_t left_count = 0;
    const hlbvh2::TopSplit split = emulate_split_lanes(bins, bounds, count, consider, &left_count);
    const uint32_t right_count = count - left_count;
    uint32_t lefts = 0;
    for (uint32_t chunk = task.first; chunk < task.end; chunk += kTaskBlock) {
        bool left[kTaskBlock] = {};
        uint32_t before[kTaskBlock] = {};  // cub::BlockScan's exclusive sum, in thread order
        uint32_t chunk_lefts = 0;
        for (uint32_t t = 0; t < kTaskBlock; ++t) {
            const uint32_t i = chunk + t;
            left[t] = i < task.end && hlbvh2::cluster_goes_left(in[i], i, task, bounds, split, left_count);
            before[t] = chunk_lefts;
            chunk_lefts += left[t] ? 1u : 0u;
        }
        std::shuffle(threads.begin(), threads.end(), rng);
        for (uint32_t t : threads) {
            const uint32_t i = chunk + t;
            if (i >= task.end) continue;
            const uint32_t slot = hlbvh2::partition_slot(task, left_count, i, lefts + before[t], left[t]);
            if (slot < task.first || slot >= task.end) {
                ++stats.bad_slots;
                continue;
            }
            out[slot] = in[i];
            if (left[t] && left_count == 1) top_refs[2 * task.node] = in[i].root;
            if (!left[t] && right_count == 1) top_refs[2 * task.node + 1] = in[i].root;
        }
        lefts += chunk_lefts;
    }
    TopTask halves[2];
    hlbvh2::child_tasks(task, left_count, halves);
    uint32_t inner = 0;
    for (int side = 0; side < 2; ++side) {
        if (halves[side].end - halves[side].first < 2) continue;
        top_refs[2 * task.node + side] = top_base + halves[side].node;
        children[inner++] = halves[side];
    }
    return inner;
}

struct QueueTop {
    std::vector<uint32_t> refs;                       // 2 per top node
    std::vector<std::vector<uint32_t>> level_nodes;   // per level, the task's node numbers
    BlockPathStats block;                             // the block path's share
};

// How the emulation splits the levels: tasks of more than block_min
// clusters take the block path (the device's kTopBlockTaskMin; lower values
// send more tasks through it), whose threads stride by block_stride.
struct TopSchedule {
    uint32_t block_min = hlbvh2::kTopBlockTaskMin;
    uint32_t block_stride = kTaskBlock;
};

// The top level's one cooperative launch (hlbvh2_top_level.cu
// top_level_kernel), level by level between grid syncs: a level's large
// tasks (a block each; the first block opening the next level record) and
// its small tasks' warps run concurrently, so they are emulated in ONE
// shuffled order, each task's children counted into the next record at
// once; two queues (small, large) ping-pong with the device's capacities;
// every level's sizes and node-list base come from its record
// (hlbvh2::TopQueueLevel), and `extra_levels` levels after the last must do
// nothing (the device stops at the first empty one).
QueueTop run_top_task_queues(std::vector<TopCluster> clusters, uint32_t top_base, uint32_t seed,
                             Consider consider = hlbvh2::consider, TopSchedule schedule = {},
                             uint32_t extra_levels = 3) {
    const uint32_t count = static_cast<uint32_t>(clusters.size());
    QueueTop top;
    if (count < 2) return top;
    top.refs.assign(2 * size_t{count - 1}, kUnset);
    std::vector<TopCluster> buffer[2] = {std::move(clusters), std::vector<TopCluster>(count)};
    const bool root_is_large = count > schedule.block_min;
    const hlbvh2::TopQueueCapacity capacity{count / 2, std::max(1u, count / (schedule.block_min + 1)), count - 1};
    std::vector<TopTask> queue[2], large_queue[2];
    for (int side = 0; side < 2; ++side) {
        queue[side].assign(capacity.small, TopTask{kUnset, kUnset, kUnset});
        large_queue[side].assign(capacity.large, TopTask{kUnset, kUnset, kUnset});
    }
    std::vector<hlbvh2::TopQueueLevel> records(size_t{count} + 1, hlbvh2::TopQueueLevel{0, 0, 0, 0, 0});
    (root_is_large ? large_queue[0] : queue[0])[0] = TopTask{0, count, 0};
    (root_is_large ? records[0].large : records[0].small) = 1;
    std::vector<uint32_t> level_nodes(capacity.nodes, kUnset);
    std::mt19937 rng(seed);
    uint32_t after_last = 0;
    for (uint32_t level = 0; level + 1 < records.size() && after_last <= extra_levels; ++level) {
        const uint32_t side = level & 1;
        const hlbvh2::TopQueueLevel self = records[level];
        hlbvh2::TopQueueLevel& next = records[level + 1];
        if (!hlbvh2::open_next_top_level(self, &next, capacity)) {
            ADD_FAILURE() << "top level " << level << " does not fit";
            break;
        }
        if (self.small + self.large == 0) ++after_last;
        const std::vector<TopTask>& input = queue[side];
        const std::vector<TopTask>& large_input = large_queue[side];
        std::vector<TopTask>& output = queue[1 - side];
        std::vector<TopTask>& large_output = large_queue[1 - side];
        uint32_t* nodes = level_nodes.data() + self.base;  // large tasks' first
        auto run_block = [&](uint32_t block) {
            TopTask children[2];
            const uint32_t inner = emulate_large_top_task(large_input[block], buffer[side].data(),
                                                          buffer[1 - side].data(), top_base, top.refs.data(),
                                                          children, consider, schedule.block_stride, rng, top.block);
            nodes[block] = large_input[block].node;
            for (uint32_t k = 0; k < inner; ++k) {
                const bool large = children[k].end - children[k].first > schedule.block_min;
                uint32_t& tail = large ? next.large : next.small;
                std::vector<TopTask>& to = large ? large_output : output;
                if (tail < to.size()) to[tail] = children[k];
                ++tail;
            }
        };
        auto run_warp = [&](uint32_t warp) {
            TopTask children[kTasksPerWarp][2];
            uint32_t inner[kTasksPerWarp] = {};
            uint32_t one_or_more = 0, two = 0;  // ballots of the tasks' lane 0s
            for (uint32_t group = 0; group < kTasksPerWarp; ++group) {
                const uint32_t at = warp * kTasksPerWarp + group;
                if (at >= self.small) continue;
                EXPECT_LE(input[at].end - input[at].first, schedule.block_min) << "a large task in the small queue";
                inner[group] = emulate_top_task(input[at], buffer[side].data(), buffer[1 - side].data(), top_base,
                                                top.refs.data(), children[group], consider);
                nodes[self.large + at] = input[at].node;
                one_or_more |= (inner[group] >= 1 ? 1u : 0u) << (group * kLanes);
                two |= (inner[group] == 2 ? 1u : 0u) << (group * kLanes);
            }
            const uint32_t base = next.small;  // the warp's atomicAdd on the next record's small count
            next.small += hlbvh2::enqueue_total(one_or_more, two);
            for (uint32_t group = 0; group < kTasksPerWarp; ++group) {
                const uint32_t offset = base + hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(group * kLanes));
                for (uint32_t k = 0; k < inner[group]; ++k) {
                    if (offset + k < output.size()) output[offset + k] = children[group][k];
                }
            }
        };
        // Work items: the large tasks' blocks, then the small tasks' warps, in one shuffled order.
        const uint32_t warps = (self.small + kTasksPerWarp - 1) / kTasksPerWarp;
        std::vector<uint32_t> items(self.large + warps);
        std::iota(items.begin(), items.end(), 0u);
        std::shuffle(items.begin(), items.end(), rng);
        for (uint32_t item : items) {
            if (item < self.large) {
                run_block(item);
            } else {
                run_warp(item - self.large);
            }
        }
    }
    // What the host reads back once.
    for (const hlbvh2::TopQueueLevel& r : records) {
        EXPECT_EQ(r.fault, 0u);
        if (r.small + r.large == 0) break;
        top.level_nodes.emplace_back(level_nodes.begin() + r.base, level_nodes.begin() + r.base + r.small + r.large);
    }
    return top;
}

// The clusters as the device's top level sees them, after the bottom levels.
std::vector<TopCluster> top_clusters(const SortedClusters& s, const BottomForest& f, std::vector<Box3f>& inner_boxes) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    std::vector<Box3f> cluster_boxes;
    run_bottom_box_pass<karras::AtomicArrival>(s, f, 1, inner_boxes, cluster_boxes);
    std::vector<TopCluster> clusters;
    for (size_t c = 0; c < s.cluster_prefix.size(); ++c) {
        const uint32_t root = f.refs[2 * (n - 1) + c];
        clusters.push_back({cluster_boxes[c], hlbvh2::pack_cells(s.cluster_prefix[c]),
                            s.cluster_begin[c + 1] - s.cluster_begin[c], root});
    }
    return clusters;
}

std::vector<NamedScene> top_scenes() {
    std::vector<NamedScene> out = scenes();
    out.push_back({"big soup", test::make_triangle_soup(40000, 2, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.05f)});
    SceneGeometry plane;  // every centroid at z = 0: every cluster in one cell-plane
    for (int x = 0; x < 40; ++x) {
        for (int y = 0; y < 40; ++y) {
            const Vec3f p{static_cast<float>(x), static_cast<float>(y) * 0.7f, 0.0f};
            test::append(plane, {p, p + Vec3f(0.3f, 0, 0), p + Vec3f(0, 0.3f, 0)});
        }
    }
    out.push_back({"one cell-plane", std::move(plane)});
    SceneGeometry lattice;  // 8^3 equal triangles on a cubic lattice: equal costs on every axis
    for (int x = 0; x < 8; ++x) {
        for (int y = 0; y < 8; ++y) {
            for (int z = 0; z < 8; ++z) {
                const Vec3f p{static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
                test::append(lattice, {p - Vec3f(0.1f), p + Vec3f(0.1f, 0.1f, -0.1f), p + Vec3f(-0.1f, 0.1f, 0.1f)});
            }
        }
    }
    out.push_back({"equal costs", std::move(lattice)});
    return out;
}

// Random distinct cells with random boxes, as the top level's only input.
std::vector<TopCluster> random_clusters(uint32_t count, uint32_t seed, float extent) {
    std::mt19937 rng(seed);
    std::vector<uint32_t> prefixes(1u << 15);
    std::iota(prefixes.begin(), prefixes.end(), 0u);
    std::shuffle(prefixes.begin(), prefixes.end(), rng);
    prefixes.resize(count);
    std::sort(prefixes.begin(), prefixes.end());
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<TopCluster> clusters;
    for (uint32_t c = 0; c < count; ++c) {
        TopCluster cl;
        const uint32_t cells = hlbvh2::pack_cells(prefixes[c]);
        const Vec3f lo{(hlbvh2::cell_of(cells, 0) + unit(rng) * 0.5f) * extent,
                       (hlbvh2::cell_of(cells, 1) + unit(rng) * 0.5f) * extent,
                       (hlbvh2::cell_of(cells, 2) + unit(rng) * 0.5f) * extent};
        cl.box.lo = lo;
        cl.box.hi = lo + Vec3f(unit(rng), unit(rng), unit(rng)) * extent;
        cl.cells = cells;
        cl.triangles = 1 + rng() % 50;
        cl.root = kLeafRef | (c * 64);
        clusters.push_back(cl);
    }
    return clusters;
}

TEST(Hlbvh2DeviceLogic, TopLevelTaskQueuesBuildTheCpuTopLevel) {
    for (const NamedScene& scene : top_scenes()) {
        for (uint32_t leaf_size : {1u, 4u}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            if (s.keys.size() < 2) continue;
            const uint32_t n = static_cast<uint32_t>(s.keys.size());
            const BottomForest f = run_bottom_launch(s, leaf_size, 5);
            std::vector<Box3f> inner_boxes;
            const std::vector<TopCluster> clusters = top_clusters(s, f, inner_boxes);
            if (scene.name == "one point") EXPECT_EQ(clusters.size(), 1u);
            if (scene.name == "two") EXPECT_EQ(clusters.size(), 2u);
            if (scene.name == "one cell-plane") {
                EXPECT_GT(clusters.size(), 8u);
                for (const TopCluster& c : clusters) EXPECT_EQ(hlbvh2::cell_of(c.cells, 2), hlbvh2::cell_of(clusters[0].cells, 2));
            }
            std::vector<TopCluster> cpu_clusters = clusters;
            const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu_clusters, n - 1);
            ASSERT_EQ(expected.size(), clusters.size() > 1 ? 2 * (clusters.size() - 1) : 0u);
            // Two warp schedules (the second seed depends on the leaf size: four in all).
            // With leaves of 1, a third sends every task of 3 or more clusters through the block path.
            QueueTop top;
            for (uint32_t seed : {1u, 2u + leaf_size, 7u}) {
                if (seed == 7u && leaf_size != 1) continue;
                const TopSchedule schedule{.block_min = seed == 7u ? 2u : hlbvh2::kTopBlockTaskMin};
                top = run_top_task_queues(clusters, n - 1, seed, hlbvh2::consider, schedule);
                EXPECT_EQ(top.refs, expected);
                EXPECT_EQ(top.block.bin_mismatches, 0u);
                EXPECT_EQ(top.block.bad_slots, 0u);
                if (clusters.size() > schedule.block_min) EXPECT_GT(top.block.tasks, 0u);
                size_t nodes = 0;
                for (const auto& level : top.level_nodes) nodes += level.size();
                EXPECT_EQ(nodes, clusters.size() > 1 ? clusters.size() - 1 : 0u) << "every task is one top node";
            }
            const BvhBuildConfig config{.max_leaf_size = static_cast<int>(leaf_size)};
            EXPECT_TRUE(same_bvh(build_hlbvh2(scene.geometry.triangles, config),
                                 emit_hlbvh2_forest(scene.geometry.triangles, config, to_forest(s, f, top.refs))));
        }
    }
}

TEST(Hlbvh2DeviceLogic, TopLevelOfRandomAndExtremeClusters) {
    // Random cells; tiny and huge boxes (areas overflowing to inf and NaN
    // costs follow the same tie rules on both sides); equal boxes (all ties).
    for (uint32_t count : {2u, 3u, 9u, 100u, 1000u, 5000u}) {
        for (float extent : {1e-30f, 1.0f, 1e18f, 1e37f, 3e37f}) {
            SCOPED_TRACE(std::to_string(count) + " clusters, extent " + std::to_string(extent));
            std::vector<TopCluster> clusters = random_clusters(count, count + 17, extent);
            std::vector<TopCluster> cpu = clusters;
            const uint32_t top_base = 64 * count;
            EXPECT_EQ(run_top_task_queues(clusters, top_base, count).refs, build_hlbvh2_top_level(cpu, top_base));
            const QueueTop blocks = run_top_task_queues(clusters, top_base, count, hlbvh2::consider, {.block_min = 2});
            EXPECT_EQ(blocks.refs, build_hlbvh2_top_level(cpu, top_base)) << "block path only";
            EXPECT_EQ(blocks.block.bin_mismatches, 0u);
            for (TopCluster& c : clusters) {
                c.box = clusters[0].box;
                c.triangles = 3;
            }
            cpu = clusters;
            EXPECT_EQ(run_top_task_queues(clusters, top_base, count + 1).refs, build_hlbvh2_top_level(cpu, top_base));
        }
    }
}

// The strided binning's reduce-scatter hands lane L bin L of each axis,
// equal to bin_task's (up to zero signs); a scatter that keeps the bins it
// sends is caught.
TEST(Hlbvh2DeviceLogic, StridedLaneBinsEqualTheSerialBins) {
    size_t checked = 0, caught = 0;
    for (uint32_t count : {33u, 40u, 64u, 200u, 256u}) {
        for (uint32_t seed = 1; seed <= 6; ++seed) {
            const std::vector<TopCluster> clusters = random_clusters(count, seed, seed % 2 ? 1.0f : 1e-3f);
            const TopTask task{0, count, 0};
            hlbvh2::CellBounds bounds = hlbvh2::empty_cell_bounds();
            for (const TopCluster& c : clusters) hlbvh2::grow(bounds, c.cells);
            TopBin serial[3][hlbvh2::kTopBins];
            hlbvh2::bin_task(clusters.data(), 0, count, bounds, serial);
            TopBin lanes[kLanes][3], wrong[kLanes][3];
            strided_bins_lanes(clusters.data(), task, bounds, lanes);
            strided_bins_lanes(clusters.data(), task, bounds, wrong, ScatterBug::KeepSent);
            bool wrong_differs = false;
            for (uint32_t lane = 0; lane < kLanes; ++lane) {
                for (int axis = 0; axis < 3; ++axis) {
                    EXPECT_TRUE(same_bin_value(lanes[lane][axis], serial[axis][lane]))
                        << count << " clusters, seed " << seed << ", lane " << lane << ", axis " << axis;
                    wrong_differs |= !same_bin_value(wrong[lane][axis], serial[axis][lane]);
                }
            }
            ++checked;
            caught += wrong_differs;
        }
    }
    EXPECT_EQ(caught, checked);
}

TEST(Hlbvh2DeviceLogic, TopLevelBlockPathIgnoresSignsOfZero) {
    // Flat clusters whose z bounds are zeros of mixed signs: the key bins'
    // min / max may pick another zero than the CPU's unions (-0 orders below
    // +0 there), which must change no cost and no choice.
    for (uint32_t count : {300u, 3000u}) {
        std::vector<TopCluster> clusters = random_clusters(count, count + 5, 1.0f);
        for (uint32_t c = 0; c < count; ++c) {
            clusters[c].box.lo.z = c % 2 != 0 ? -0.0f : 0.0f;
            clusters[c].box.hi.z = c % 3 != 0 ? 0.0f : -0.0f;
            if (c % 5 == 0) clusters[c].box.lo.x = clusters[c].box.hi.x = c % 10 == 0 ? -0.0f : 0.0f;
        }
        std::vector<TopCluster> cpu = clusters;
        const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu, 64 * count);
        for (uint32_t block_min : {2u, hlbvh2::kTopBlockTaskMin}) {
            const QueueTop top = run_top_task_queues(clusters, 64 * count, block_min, hlbvh2::consider, {.block_min = block_min});
            EXPECT_EQ(top.refs, expected);
            EXPECT_EQ(top.block.bin_mismatches, 0u);
            EXPECT_GT(top.block.tasks, 0u);
            if (block_min == 2) EXPECT_GT(top.block.zero_signs, 0u) << "no zero of another sign was met";
        }
    }
}

// A soup spread over the whole grid: thousands of occupied 15-bit cells, so
// the first levels' tasks (up to ~30,000 clusters) take the block path.
struct SpreadSoup {
    SceneGeometry geometry;
    SortedClusters sorted;
    BottomForest forest;
    std::vector<TopCluster> clusters;
};
const SpreadSoup& spread_soup() {
    static const SpreadSoup soup = [] {
        SpreadSoup s;
        s.geometry = test::make_triangle_soup(60000, 11, {Vec3f(-20.0f), Vec3f(20.0f)}, 0.1f);
        s.sorted = sort_and_cluster(s.geometry.triangles);
        s.forest = run_bottom_launch(s.sorted, 4, 3);
        std::vector<Box3f> inner_boxes;
        s.clusters = top_clusters(s.sorted, s.forest, inner_boxes);
        return s;
    }();
    return soup;
}

TEST(Hlbvh2DeviceLogic, TopLevelBlockPathOnASpreadSoup) {
    const SpreadSoup& soup = spread_soup();
    ASSERT_GE(soup.clusters.size(), 5000u);
    const uint32_t n = static_cast<uint32_t>(soup.sorted.keys.size());
    std::vector<TopCluster> cpu = soup.clusters;
    const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu, n - 1);
    QueueTop top;
    for (uint32_t seed : {1u, 2u, 3u}) {
        top = run_top_task_queues(soup.clusters, n - 1, seed);
        EXPECT_EQ(top.refs, expected);
        EXPECT_EQ(top.block.bin_mismatches, 0u);
        EXPECT_EQ(top.block.bad_slots, 0u);
        EXPECT_GE(top.block.tasks, soup.clusters.size() / (2 * hlbvh2::kTopBlockTaskMin)) << "the block path ran";
        EXPECT_EQ(top.level_nodes[0].size(), 1u);
    }
    const BvhBuildConfig config{.max_leaf_size = 4};
    EXPECT_TRUE(same_bvh(build_hlbvh2(soup.geometry.triangles, config),
                         emit_hlbvh2_forest(soup.geometry.triangles, config, to_forest(soup.sorted, soup.forest, top.refs))));
}

TEST(Hlbvh2DeviceLogic, WrongBlockStrideIsCaught) {
    const SpreadSoup& soup = spread_soup();
    const uint32_t n = static_cast<uint32_t>(soup.sorted.keys.size());
    std::vector<TopCluster> cpu = soup.clusters;
    const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu, n - 1);
    // One too few: some clusters binned twice; one too many: some never.
    for (uint32_t stride : {kTaskBlock - 1, kTaskBlock + 1}) {
        SCOPED_TRACE("stride " + std::to_string(stride));
        const QueueTop wrong = run_top_task_queues(soup.clusters, n - 1, 1, hlbvh2::consider, {.block_stride = stride});
        EXPECT_GT(wrong.block.bin_mismatches, 0u);
        EXPECT_NE(wrong.refs, expected);
    }
}

// The top boxes' launches (hlbvh2_top_level.cu): the parent links, then one
// walk per top node, in a shuffled order, top boxes poisoned before.
template <class Arrival>
std::vector<Box3f> run_top_box_pass(const hlbvh2::BoxView& bottom, const std::vector<uint32_t>& top_refs, uint32_t n,
                                    uint32_t seed) {
    const uint32_t top_nodes = static_cast<uint32_t>(top_refs.size() / 2);
    Box3f poison;
    poison.lo = Vec3f(1e30f);
    poison.hi = Vec3f(-1e30f);
    std::vector<Box3f> top_boxes(top_nodes, poison);
    std::vector<uint32_t> parents(top_nodes, kUnset), arrivals(top_nodes, 0);
    const hlbvh2::TopBoxView view{bottom, top_refs.data(), n - 1, top_boxes.data()};
    for (uint32_t k : shuffled(top_nodes, seed)) hlbvh2::link_top_children(view, k, parents.data());
    for (uint32_t k : shuffled(top_nodes, seed + 1)) {
        hlbvh2::top_boxes_from_node<Arrival>(view, parents.data(), arrivals.data(), k);
    }
    return top_boxes;
}

TEST(Hlbvh2DeviceLogic, TopLevelBoxesAreTheLevelWiseBoxes) {
    const SortedClusters s = sort_and_cluster(test::make_triangle_soup(20000, 8, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.2f).triangles);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const BottomForest f = run_bottom_launch(s, 4, 2);
    std::vector<Box3f> inner_boxes;
    const std::vector<TopCluster> clusters = top_clusters(s, f, inner_boxes);
    ASSERT_GT(clusters.size(), 100u);
    const QueueTop top = run_top_task_queues(clusters, n - 1, 4);
    const hlbvh2::BoxView bottom{f.refs.data(), f.leaf_runs.data(), s.order.data(), s.triangle_boxes.data(),
                                 inner_boxes.data()};
    // The level-wise pass it replaces: union(left, right), children (numbered above their parent) first.
    std::vector<Box3f> expected(clusters.size() - 1);
    const hlbvh2::TopBoxView expected_view{bottom, top.refs.data(), n - 1, expected.data()};
    for (size_t k = expected.size(); k-- > 0;) {
        expected[k] = hlbvh2::box_union(hlbvh2::top_child_box(expected_view, top.refs[2 * k]),
                                        hlbvh2::top_child_box(expected_view, top.refs[2 * k + 1]));
    }
    Box3f all = clusters[0].box;
    for (const TopCluster& c : clusters) all = hlbvh2::box_union(all, c.box);
    EXPECT_TRUE(same_box(expected[0], all));
    for (uint32_t seed : {1u, 5u, 9u}) {
        const std::vector<Box3f> got = run_top_box_pass<karras::AtomicArrival>(bottom, top.refs, n, seed);
        size_t wrong = 0;
        for (size_t k = 0; k < got.size(); ++k) wrong += !same_box(got[k], expected[k]);
        EXPECT_EQ(wrong, 0u) << "seed " << seed;
    }
    const std::vector<Box3f> bad = run_top_box_pass<FirstArrivalContinues>(bottom, top.refs, n, 1);
    size_t differ = 0;
    for (size_t k = 0; k < bad.size(); ++k) differ += !same_box(bad[k], expected[k]);
    EXPECT_GT(differ, 0u) << "a walk going on at the first arrival must be caught";
}

TEST(Hlbvh2DeviceLogic, WrongTopTieRuleIsCaught) {
    const std::vector<NamedScene> all = top_scenes();
    const SceneGeometry& g = all.back().geometry;  // equal costs
    const SortedClusters s = sort_and_cluster(g.triangles);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const BottomForest f = run_bottom_launch(s, 1, 1);
    std::vector<Box3f> inner_boxes;
    const std::vector<TopCluster> clusters = top_clusters(s, f, inner_boxes);
    std::vector<TopCluster> cpu = clusters;
    const QueueTop wrong = run_top_task_queues(clusters, n - 1, 1, consider_last_of_equals);
    EXPECT_NE(wrong.refs, build_hlbvh2_top_level(cpu, n - 1));
    const BvhBuildConfig config{.max_leaf_size = 1};
    EXPECT_FALSE(same_bvh(build_hlbvh2(g.triangles, config),
                          emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, wrong.refs))));
}

TEST(Hlbvh2DeviceLogic, MalformedTopLevelThrows) {
    const SceneGeometry g = test::make_triangle_soup(2000, 4, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.2f);
    const SortedClusters s = sort_and_cluster(g.triangles);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const BottomForest f = run_bottom_launch(s, 1, 1);
    std::vector<Box3f> inner_boxes;
    const std::vector<uint32_t> good = run_top_task_queues(top_clusters(s, f, inner_boxes), n - 1, 1).refs;
    ASSERT_GT(good.size(), 4u);
    const BvhBuildConfig config{.max_leaf_size = 1};
    EXPECT_NO_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, good)));
    std::vector<uint32_t> bad = good;
    bad[2] = n - 1;  // a child replaced by the root: a cycle
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, bad)), Error);
    bad = good;
    bad.back() = bad.front();  // a reference used twice
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, bad)), Error);
    bad = good;
    bad.pop_back();
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, bad)), Error);
}

}  // namespace
}  // namespace rf
