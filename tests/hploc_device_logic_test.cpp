// The device half of H-PLOC (Benthin et al. 2024; backend/cuda/hploc_build.cu)
// checked on the CPU: the kernel's warps (hploc_steps.h's warp_round on a
// SimulatedWarp, whose shuffles and ballots read every lane as the device's
// do) with the device's memory layout (children and node boxes in creation
// order, leaf boxes gathered through the sorted order, plain exchanges for
// the atomics), the warps' rounds interleaved in shuffled orders as the
// device's scheduler may run them; the clustering, emitted by
// emit_hploc_tree, must be build_hploc's BVH exactly. Also: Apetrei's
// climb finds Karras's radix tree, the warp's nearest-neighbour search finds
// PLOC's neighbours, node boxes are their children's unions, and a
// deliberate bug (slots not emptied behind a range's clusters) is caught.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "accel_test_scenes.h"
#include "accel/bvh/builders/hploc.h"
#include "accel/bvh/builders/hploc_steps.h"
#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel/bvh/builders/ploc_steps.h"
#include "bvh_invariants.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using hploc::kLeafRef;
using hploc::kWarpLanes;

enum class Bug { None, StaleSlots };

// The device's memory (hploc_build.cu's DeviceMemory), single-threaded.
struct DeviceLikeMemory {
    std::vector<uint32_t>* clusters;
    const std::vector<Box3f>* triangle_boxes;
    const std::vector<uint32_t>* order;
    std::vector<uint32_t>* children;
    std::vector<Box3f>* node_boxes;
    Bug bug = Bug::None;
    mutable bool overflow = false;  // a node numbered past n - 2, or a ref past the arrays (only a bug makes one)

    uint32_t load_ref(uint32_t position) const { return (*clusters)[position]; }
    void store_ref(uint32_t position, uint32_t ref) const {
        if (bug == Bug::StaleSlots && ref == hploc::kNoCluster) return;
        (*clusters)[position] = ref;
    }
    // An injected bug can hand out a ref past the arrays: counted as an
    // overflow (the replay then fails) instead of read out of bounds.
    Box3f box(uint32_t ref) const {
        const bool leaf = (ref & kLeafRef) != 0;
        const uint32_t index = ref & ~kLeafRef;
        if (leaf ? index >= order->size() : index >= node_boxes->size()) {
            overflow = true;
            return Box3f{};
        }
        return leaf ? (*triangle_boxes)[(*order)[index]] : (*node_boxes)[index];
    }
    void write_node(uint32_t node, uint32_t left, uint32_t right, const Box3f& box) {
        if (node >= node_boxes->size()) {
            overflow = true;
            return;
        }
        (*children)[2 * size_t{node}] = left;
        (*children)[2 * size_t{node} + 1] = right;
        (*node_boxes)[node] = box;
    }
    uint32_t exchange(uint32_t* slot, uint32_t value) const { return std::exchange(*slot, value); }
    void publish() const {}
};

struct SortedScene {
    std::vector<uint64_t> keys;
    std::vector<uint32_t> order;
    std::vector<Box3f> triangle_boxes;
};

SortedScene sort_scene(std::span<const Triangle> triangles) {
    morton::RawTree tree(triangles, BvhBuildConfig{});
    morton::Buffer<uint64_t> keys;
    tree.sort_by_morton_codes(keys);
    SortedScene s;
    s.keys.assign(keys.data(), keys.data() + tree.size());
    s.order = tree.order;
    for (const Triangle& t : triangles) s.triangle_boxes.push_back(morton::triangle_box(t));
    return s;
}

struct Replay {
    std::vector<uint32_t> order;
    std::vector<uint32_t> children;
    std::vector<Box3f> node_boxes;
    uint32_t nodes_made = 0;
    bool failed = false;
};

// The kernel (n >= 2): one lane per leaf, warps of 32; each step runs one
// round of a warp picked at random among those with climbing lanes.
Replay replay_kernel(std::span<const Triangle> triangles, int radius, uint32_t seed, Bug bug = Bug::None) {
    const SortedScene sorted = sort_scene(triangles);
    const uint32_t n = static_cast<uint32_t>(sorted.order.size());
    Replay out;
    out.order = sorted.order;
    out.children.assign(2 * size_t{n - 1}, 0xdeadbeefu);
    out.node_boxes.resize(n - 1);
    std::vector<uint32_t> clusters(n), slots(n - 1, hploc::kNoRangeEnd);
    for (uint32_t i = 0; i < n; ++i) clusters[i] = kLeafRef | i;
    DeviceLikeMemory memory{&clusters, &sorted.triangle_boxes, &sorted.order, &out.children, &out.node_boxes, bug};
    const hploc::Build build{sorted.keys.data(), n, slots.data(), &out.nodes_made, hploc::clamp_radius(radius)};
    const uint32_t warps = (n + kWarpLanes - 1) / kWarpLanes;
    std::vector<hploc::LaneArray<hploc::Range>> lanes(warps);
    std::vector<uint32_t> live(warps);
    for (uint32_t w = 0; w < warps; ++w) {
        for (uint32_t lane = 0; lane < kWarpLanes; ++lane) lanes[w][lane] = hploc::leaf_range(w * kWarpLanes + lane, n);
        live[w] = w;
    }
    std::mt19937 rng(seed);
    hploc::SimulatedWarp warp;
    while (!live.empty()) {
        const size_t pick = std::uniform_int_distribution<size_t>(0, live.size() - 1)(rng);
        if (!hploc::warp_round(warp, memory, build, lanes[live[pick]], &out.failed)) {
            live[pick] = live.back();
            live.pop_back();
        }
    }
    out.failed = out.failed || memory.overflow;
    return out;
}

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(5000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    SceneGeometry point;  // every triangle in one point: equal codes, equal boxes
    for (int i = 0; i < 700; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    scenes.push_back({"one point", std::move(point)});
    scenes.push_back({"morton chain", test::make_morton_chain(300)});  // deeper than kBvhMaxDepth
    for (int count : {2, 3, 17, 33, 64}) {
        scenes.push_back({std::to_string(count) + " triangles",
                          test::make_triangle_soup(static_cast<size_t>(count), 9, {Vec3f(0.0f), Vec3f(1.0f)}, 0.1f)});
    }
    return scenes;
}

TEST(HplocDeviceLogic, ShuffledWarpSchedulesGiveTheCpuBvh) {
    for (const NamedScene& scene : test_scenes()) {
        for (int radius : {1, 4, 16, 31}) {
            const BvhBuildConfig config{.max_leaf_size = radius == 4 ? 1 : 4};
            const Bvh expected = build_hploc(scene.geometry.triangles, config, {.radius = radius});
            for (uint32_t seed : {1u, 2u}) {
                SCOPED_TRACE(scene.name + ", radius " + std::to_string(radius) + ", seed " + std::to_string(seed));
                Replay replay = replay_kernel(scene.geometry.triangles, radius, seed);
                ASSERT_FALSE(replay.failed);
                ASSERT_EQ(replay.nodes_made, scene.geometry.triangles.size() - 1);
                const Bvh got = emit_hploc_tree(scene.geometry.triangles, config, std::move(replay.order), replay.children);
                EXPECT_TRUE(test::identical(expected, got));
            }
        }
    }
}

// Every node's box as the device writes it: the union of its children's.
TEST(HplocDeviceLogic, NodeBoxesAreTheirChildrensUnions) {
    const SceneGeometry g = test::make_nasty_geometry(3);
    const SortedScene sorted = sort_scene(g.triangles);
    const Replay replay = replay_kernel(g.triangles, 16, 7);
    ASSERT_FALSE(replay.failed);
    auto box_of = [&](uint32_t ref) {
        return (ref & kLeafRef) != 0 ? sorted.triangle_boxes[sorted.order[ref & ~kLeafRef]] : replay.node_boxes[ref];
    };
    for (size_t node = 0; node < replay.node_boxes.size(); ++node) {
        const Box3f expected = karras::box_union(box_of(replay.children[2 * node]), box_of(replay.children[2 * node + 1]));
        ASSERT_TRUE(test::same_box(expected, replay.node_boxes[node])) << node;
    }
}

// Apetrei's bottom-up pass meets at exactly Karras's inner nodes: the same
// (left, split, right) ranges as karras::build_inner's top-down ones.
TEST(HplocDeviceLogic, ClimbFindsKarrasRadixTree) {
    for (const NamedScene& scene : test_scenes()) {
        SCOPED_TRACE(scene.name);
        const SortedScene sorted = sort_scene(scene.geometry.triangles);
        const uint32_t n = static_cast<uint32_t>(sorted.keys.size());
        std::set<std::tuple<uint32_t, uint32_t, uint32_t>> karras_nodes, climbed;
        // Top down from the root (node 0 over [0, n - 1]): a node's left
        // child ends at its split gamma.
        struct Item {
            uint32_t node, left, right;
        };
        std::vector<Item> stack{{0, 0, n - 1}};
        while (!stack.empty()) {
            const Item item = stack.back();
            stack.pop_back();
            uint32_t child[2];
            karras::build_inner(sorted.keys.data(), n, item.node, child, nullptr, nullptr);
            const uint32_t gamma = child[0] & ~kLeafRef;
            karras_nodes.insert({item.left, gamma + 1, item.right});
            if ((child[0] & kLeafRef) == 0) stack.push_back({child[0], item.left, gamma});
            if ((child[1] & kLeafRef) == 0) stack.push_back({child[1], gamma + 1, item.right});
        }
        std::vector<uint32_t> slots(n - 1, hploc::kNoRangeEnd);
        DeviceLikeMemory memory{};
        std::mt19937 rng(3);
        std::vector<uint32_t> leaves(n);
        std::iota(leaves.begin(), leaves.end(), 0u);
        std::shuffle(leaves.begin(), leaves.end(), rng);
        for (uint32_t leaf : leaves) {
            hploc::Range r = hploc::leaf_range(leaf, n);
            while (hploc::range_size(r) < n && hploc::climb(sorted.keys.data(), n, slots.data(), memory, r)) {
                climbed.insert({r.left, r.split, r.right});
            }
        }
        EXPECT_EQ(climbed, karras_nodes);
    }
}

// The warp's register search equals PLOC's plain search, ties included.
TEST(HplocDeviceLogic, WarpNeighbourSearchEqualsPloc) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0.0f, 4.0f);
    hploc::SimulatedWarp warp;
    for (int trial = 0; trial < 400; ++trial) {
        const uint32_t count = 2 + static_cast<uint32_t>(trial % 31);
        const uint32_t radius = 1 + static_cast<uint32_t>(rng() % hploc::kMaxRadius);
        hploc::LaneArray<Box3f> box;
        std::vector<Box3f> boxes(count);
        for (uint32_t lane = 0; lane < kWarpLanes; ++lane) {
            // Coarse values on odd trials: many equal areas, so the tie rule decides.
            const float q = trial % 2 ? 1.0f : 0.0f;
            auto value = [&] { return q != 0.0f ? std::floor(u(rng)) : u(rng); };
            const Vec3f a(value(), value(), value());
            box[lane] = Box3f{a, a + Vec3f(value(), value(), value())};
            if (lane < count) boxes[lane] = box[lane];
        }
        const hploc::LaneArray<uint32_t> neighbour = hploc::nearest_neighbours(warp, box, count, radius);
        for (uint32_t lane = 0; lane < count; ++lane) {
            ASSERT_EQ(neighbour[lane], ploc::nearest_neighbour(boxes.data(), count, radius, lane))
                << "trial " << trial << " lane " << lane;
        }
    }
}

TEST(HplocDeviceLogic, NthSetLane) {
    EXPECT_EQ(hploc::nth_set_lane(0b1011u, 0, 99), 0u);
    EXPECT_EQ(hploc::nth_set_lane(0b1011u, 1, 99), 1u);
    EXPECT_EQ(hploc::nth_set_lane(0b1011u, 2, 99), 3u);
    EXPECT_EQ(hploc::nth_set_lane(0b1011u, 3, 99), 99u);
    EXPECT_EQ(hploc::nth_set_lane(0x80000000u, 0, 99), 31u);
    EXPECT_EQ(hploc::nth_set_lane(0u, 0, 5), 5u);
}

// The replay must be able to fail: slots left holding stale clusters behind
// a range's survivors are loaded again by its parent.
TEST(HplocDeviceLogic, CatchesStaleSlots) {
    const SceneGeometry g = test::make_triangle_soup(3000, 4, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f);
    Replay replay = replay_kernel(g.triangles, 16, 1, Bug::StaleSlots);
    bool caught = replay.failed || replay.nodes_made != g.triangles.size() - 1;
    if (!caught) {
        try {
            const Bvh got = emit_hploc_tree(g.triangles, {}, std::move(replay.order), replay.children);
            caught = !test::identical(got, build_hploc(g.triangles, {}, {}));
        } catch (const Error&) {
            caught = true;
        }
    }
    EXPECT_TRUE(caught);
}

}  // namespace
}  // namespace rf
