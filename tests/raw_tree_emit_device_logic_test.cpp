// The device emission of Morton-family raw trees (src/accel/bvh/builders/
// raw_tree_emit_steps.h, run by backend/cuda/raw_tree_emit.cu) replayed on
// the CPU the way the kernels run it: parents scattered per node slot, one
// bottom-up walker per leaf with "second arrival continues" counters, and
// the top-down emission one level (launch) at a time, each launch's threads
// in shuffled order; and the device's one-launch form (emit_node: each node
// slot sums its position over its ancestors) must equal it bit for bit. The result must be morton::RawTree::emit's, bit for bit, on random
// trees (any leaf order, as PLOC makes; leaf runs, as HLBVH2 makes; unused
// node slots and a separate top-level array, as HLBVH2 numbers them) and on
// the LBVH's Karras trees; trees deeper than kBvhMaxDepth must be refused
// exactly when the host emitter needs its depth-limited rebuild.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/lbvh.h"
#include "accel/bvh/builders/lbvh_emit.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel/bvh/builders/ploc.h"
#include "accel/bvh/builders/raw_tree_emit_steps.h"
#include "accel_test_scenes.h"
#include "bvh_hash.h"

namespace rf {
namespace {

using raw_emit::kLeafRef;
using raw_emit::kNoChild;
using raw_emit::kNoParent;

// One thread at a time: the first arrival reads 0 and stops.
struct SequentialArrival {
    static uint32_t arrive(uint32_t* counter) { return (*counter)++; }
};
struct SequentialCounter {
    static uint32_t add(uint32_t* counter, uint32_t n) {
        const uint32_t before = *counter;
        *counter += n;
        return before;
    }
};
// A deliberate bug: the first arrival goes on instead of the second, so a
// node is computed before its other child is final.
struct FirstArrivalContinues {
    static uint32_t arrive(uint32_t* counter) { return (*counter)++ == 0 ? 1u : 0u; }
};

// A raw tree as a device builder leaves it.
struct RawInput {
    std::vector<uint32_t> order;          // sorted position -> triangle
    std::vector<uint32_t> children;       // 2 per node slot (kNoChild: unused)
    uint32_t high_base = 0;               // slots from here on read the "top level" array
    uint32_t root = 0;
    std::vector<uint8_t> runs;            // per leaf start; empty: single-primitive leaves
};

using morton::triangle_box;

struct Emulated {
    bool fits = false;
    Bvh bvh;         // the per-level emission
    Bvh one_launch;  // emit_node over every node slot (node roots only)
    size_t wrong_positions = 0;  // node slots whose locate_node differs from the item the levels queued
    std::vector<raw_emit::NodeInfo> info;  // per node slot, after the bottom-up pass
};

// `sparse`: node values stored for the used slots only, through the prefix
// sum of used_slot() (as the device does for HLBVH2).
template <class Arrival = SequentialArrival>
Emulated emulate(std::span<const Triangle> triangles, const BvhBuildConfig& config, const RawInput& in,
                 uint32_t seed, bool sparse = false) {
    const uint32_t n = static_cast<uint32_t>(in.order.size());
    const uint32_t slots = static_cast<uint32_t>(in.children.size() / 2);
    std::vector<Box3f> boxes(n);  // per triangle, as the device keeps them
    for (uint32_t i = 0; i < n; ++i) boxes[i] = triangle_box(triangles[i]);
    const std::vector<uint32_t> low(in.children.begin(), in.children.begin() + 2 * size_t{in.high_base});
    const std::vector<uint32_t> high(in.children.begin() + 2 * size_t{in.high_base}, in.children.end());
    std::vector<uint32_t> node_parent(slots, kNoParent), leaf_parent(n, kNoParent), arrivals(slots, 0);
    std::vector<raw_emit::NodeInfo> info(slots);
    std::memset(static_cast<void*>(info.data()), 0xcd, info.size() * sizeof(raw_emit::NodeInfo));

    raw_emit::RawTreeView view{};
    view.children = low.data();
    view.high_children = high.empty() ? nullptr : high.data();
    view.high_base = in.high_base;
    view.node_slots = slots;
    view.root = in.root;
    view.primitives = n;
    view.boxes = boxes.data();
    view.boxes_by_triangle = true;
    view.order = in.order.data();
    view.leaf_runs = in.runs.empty() ? nullptr : in.runs.data();
    view.node_parent = node_parent.data();
    view.leaf_parent = leaf_parent.data();
    view.info = info.data();
    view.arrivals = arrivals.data();
    view.costs = {config.sah.traversal, config.sah.intersection,
                  static_cast<uint32_t>(std::clamp(config.max_leaf_size, 1, 255))};

    std::mt19937 rng(seed);
    auto shuffled = [&](uint32_t count) {
        std::vector<uint32_t> ids(count);
        std::iota(ids.begin(), ids.end(), 0u);
        std::shuffle(ids.begin(), ids.end(), rng);
        return ids;
    };
    for (uint32_t s : shuffled(slots)) raw_emit::scatter_parents(view, s);
    std::vector<uint32_t> dense;
    if (sparse) {
        dense.assign(size_t{slots} + 1, 0u);
        for (uint32_t s = 0; s < slots; ++s) dense[s + 1] = dense[s] + raw_emit::used_slot(view, s);
        info.assign(dense[slots], raw_emit::NodeInfo{});
        std::memset(static_cast<void*>(info.data()), 0xcd, info.size() * sizeof(raw_emit::NodeInfo));
        arrivals.assign(dense[slots], 0u);
        view.dense = dense.data();
        view.info = info.data();
        view.arrivals = arrivals.data();
    }
    for (uint32_t p : shuffled(n)) raw_emit::finalize_from_leaf<Arrival>(view, p);

    Emulated out;
    // Per slot, for the comparison with the host (unused slots stay poisoned).
    out.info.assign(slots, raw_emit::NodeInfo{});
    for (uint32_t s = 0; s < slots; ++s) {
        if (raw_emit::used_slot(view, s)) out.info[s] = raw_emit::node_info(view, s);
    }
    const bool leaf_root = raw_emit::is_leaf_ref(in.root);
    out.fits = leaf_root || raw_emit::fits_depth_limit(raw_emit::node_info(view, in.root));
    if (!out.fits) return out;
    out.bvh.nodes.resize(leaf_root ? 1u : raw_emit::node_info(view, in.root).out_size);
    out.bvh.prim_indices.assign(n, 0xdeadbeefu);
    BvhNode poison;
    std::memset(static_cast<void*>(&poison), 0xcd, sizeof poison);
    std::fill(out.bvh.nodes.begin(), out.bvh.nodes.end(), poison);
    if (leaf_root) {
        std::vector<raw_emit::EmitItem> next(1);
        uint32_t next_count = 0;
        raw_emit::emit_item<SequentialCounter>(view, raw_emit::root_item(in.root), out.bvh.nodes.data(),
                                               out.bvh.prim_indices.data(), next.data(), &next_count);
        EXPECT_EQ(next_count, 0u);
        return out;
    }
    // One launch per level, its items in shuffled order.
    const raw_emit::NodeInfo root = raw_emit::node_info(view, in.root);
    const uint32_t levels = raw_emit::emit_levels(root);
    std::vector<raw_emit::EmitItem> items{raw_emit::root_item(in.root)};
    const raw_emit::EmitItem none{kNoChild, 0, 0, 0};
    std::vector<raw_emit::EmitItem> queued(slots, none);  // per node slot, the item a level gave it
    for (uint32_t level = 0; level < levels; ++level) {
        std::vector<raw_emit::EmitItem> next(root.out_size);
        uint32_t next_count = 0;
        for (uint32_t i : shuffled(static_cast<uint32_t>(items.size()))) {
            raw_emit::emit_item<SequentialCounter>(view, items[i], out.bvh.nodes.data(), out.bvh.prim_indices.data(),
                                                   next.data(), &next_count);
            if (!raw_emit::is_leaf_ref(items[i].ref)) queued[items[i].ref] = items[i];
        }
        EXPECT_LE(next_count, (root.out_size + 1) / 2) << "a level wider than the device's buffers";
        next.resize(next_count);
        items = std::move(next);
    }
    EXPECT_TRUE(items.empty()) << "items queued below the root's height";
    // The device's form: one launch, a thread per node slot in shuffled order.
    out.one_launch.nodes.assign(out.bvh.nodes.size(), poison);
    out.one_launch.prim_indices.assign(n, 0xdeadbeefu);
    for (uint32_t s : shuffled(slots)) {
        raw_emit::emit_node(view, s, out.one_launch.nodes.data(), out.one_launch.prim_indices.data());
    }
    // Each node slot's position from its ancestors: the queued item, or none
    // (unused, or below a collapsed node).
    for (uint32_t s = 0; s < slots; ++s) {
        raw_emit::EmitItem located = none;
        if (!raw_emit::locate_node(view, s, &located)) located = none;
        out.wrong_positions += std::memcmp(&located, &queued[s], sizeof located) != 0;
    }
    return out;
}

// The host's emission of the same tree: RawTree finalized bottom-up, then emit().
struct HostEmission {
    bool needs_rebuild = false;  // the root's emitted height exceeds kBvhMaxDepth
    Bvh bvh;
    std::vector<morton::RawNode> nodes;  // per node slot, finalized (before emit's depth planning)
    std::vector<uint32_t> used_slots;
};

HostEmission host_emit(std::span<const Triangle> triangles, const BvhBuildConfig& config, const RawInput& in) {
    morton::RawTree tree(triangles, config);
    tree.set_order(std::vector<uint32_t>(in.order));
    if (!in.runs.empty()) {
        tree.enable_leaf_runs();
        for (uint32_t p = 0; p < in.runs.size(); ++p) {
            if (in.runs[p] != 0) tree.set_leaf_run(p, in.runs[p]);
        }
    }
    const uint32_t slots = static_cast<uint32_t>(in.children.size() / 2);
    tree.nodes.resize(slots);
    // Post-order over the tree from the root (an explicit stack: chains may be deep).
    HostEmission out;
    if (!morton::is_leaf_ref(in.root)) {
        std::vector<std::pair<uint32_t, bool>> stack{{in.root, false}};
        while (!stack.empty()) {
            auto [node, expanded] = stack.back();
            stack.pop_back();
            const uint32_t left = in.children[2 * size_t{node}], right = in.children[2 * size_t{node} + 1];
            if (expanded) {
                tree.finalize(node, left, right);
                out.used_slots.push_back(node);
                continue;
            }
            stack.push_back({node, true});
            for (uint32_t c : {right, left}) {
                if (!morton::is_leaf_ref(c)) stack.push_back({c, false});
            }
        }
        out.nodes = tree.nodes;
        const morton::RawNode& root = tree.nodes[in.root];
        out.needs_rebuild = !(root.flags & morton::kCollapsed) && root.height > kBvhMaxDepth;
    }
    out.bvh = tree.emit(in.root);
    return out;
}

bool same_bvh(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() && a.prim_indices == b.prim_indices &&
           (a.nodes.empty() || std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode)) == 0);
}

enum class Shape { kRandom, kChain, kBalanced };

// A random raw tree over n primitives: leaf runs of 1..max_run sorted
// positions, taken in sorted order or shuffled (PLOC's leaves are in any
// order), joined by random, chain-like or balanced splits; node slots drawn
// from a larger space (gaps stay kNoChild), the top `high` share of slots
// standing for HLBVH2's separate top-level array.
RawInput random_tree(uint32_t n, uint32_t max_run, bool shuffle_leaves, Shape shape, uint32_t seed) {
    std::mt19937 rng(seed);
    RawInput in;
    in.order.resize(n);
    std::iota(in.order.begin(), in.order.end(), 0u);
    std::shuffle(in.order.begin(), in.order.end(), rng);  // any Morton order
    std::vector<uint32_t> leaves;
    if (max_run > 1) in.runs.assign(n, 0);
    for (uint32_t p = 0; p < n;) {
        const uint32_t run = std::min(n - p, 1 + static_cast<uint32_t>(rng() % max_run));
        if (max_run > 1) in.runs[p] = static_cast<uint8_t>(run);
        leaves.push_back(kLeafRef | p);
        p += run;
    }
    if (shuffle_leaves) std::shuffle(leaves.begin(), leaves.end(), rng);
    const uint32_t inner = static_cast<uint32_t>(leaves.size()) - 1;
    const uint32_t slots = inner + inner / 3 + 1;  // about a quarter unused
    std::vector<uint32_t> free_slots(slots);
    std::iota(free_slots.begin(), free_slots.end(), 0u);
    std::shuffle(free_slots.begin(), free_slots.end(), rng);
    in.children.assign(2 * size_t{slots}, kNoChild);
    in.high_base = slots - slots / 4;
    uint32_t next_slot = 0;
    // Iterative construction over leaf ranges: (first, end, slot of the parent's reference).
    struct Range {
        uint32_t first, end;
        uint32_t* ref;
    };
    std::vector<Range> work{{0, static_cast<uint32_t>(leaves.size()), &in.root}};
    while (!work.empty()) {
        const Range r = work.back();
        work.pop_back();
        if (r.end - r.first == 1) {
            *r.ref = leaves[r.first];
            continue;
        }
        const uint32_t node = free_slots[next_slot++];
        *r.ref = node;
        const uint32_t count = r.end - r.first;
        uint32_t split;
        switch (shape) {
            case Shape::kChain: split = r.first + 1; break;
            case Shape::kBalanced: split = r.first + (count + 1) / 2; break;
            default: split = r.first + 1 + static_cast<uint32_t>(rng() % (count - 1)); break;
        }
        work.push_back({r.first, split, &in.children[2 * size_t{node}]});
        work.push_back({split, r.end, &in.children[2 * size_t{node} + 1]});
    }
    return in;
}

SceneGeometry mixed_triangles(uint32_t n, uint32_t seed) {
    // Varied sizes, so that the SAH collapses some subtrees and not others.
    SceneGeometry g = test::make_triangle_soup(n, seed, Box3f(Vec3f(-4.0f), Vec3f(4.0f)), 0.6f);
    std::mt19937 rng(seed);
    for (size_t i = 0; i < g.triangles.size(); i += 7) {
        const float s = 1.0f + static_cast<float>(rng() % 16);
        g.triangles[i].v1 = g.triangles[i].v0 + (g.triangles[i].v1 - g.triangles[i].v0) * s;
    }
    return g;
}

// Every node's finalized values, bit for bit (the SAH costs decide collapses,
// so their rounding must match even where no collapse flips).
void expect_same_values(const Emulated& device, const HostEmission& host, const std::string& what) {
    for (uint32_t slot : host.used_slots) {
        const raw_emit::NodeInfo& d = device.info[slot];
        const morton::RawNode& h = host.nodes[slot];
        const bool collapsed = (h.flags & morton::kCollapsed) != 0;
        const bool same = std::memcmp(&d.box, &h.box, sizeof(Box3f)) == 0 && d.count == h.count &&
                          std::memcmp(&d.cost, &h.cost, sizeof(float)) == 0 && d.out_size == h.out_size &&
                          raw_emit::info_collapsed(d) == collapsed && raw_emit::info_height(d) == h.height;
        if (!same) {
            ADD_FAILURE() << what << ": node slot " << slot << " differs";
            return;
        }
    }
}

void check_against_host(const SceneGeometry& g, const BvhBuildConfig& config, const RawInput& in, uint32_t seed,
                        const std::string& what) {
    const HostEmission host = host_emit(g.triangles, config, in);
    for (bool sparse : {false, true}) {
        const std::string case_name = what + (sparse ? ", values by used slot" : "");
        const Emulated device = emulate(g.triangles, config, in, seed, sparse);
        expect_same_values(device, host, case_name);
        ASSERT_EQ(device.fits, !host.needs_rebuild) << case_name;
        if (device.fits) {
            EXPECT_TRUE(same_bvh(device.bvh, host.bvh)) << case_name;
            if (!raw_emit::is_leaf_ref(in.root)) {
                EXPECT_TRUE(same_bvh(device.one_launch, device.bvh)) << case_name << ": one launch";
                EXPECT_EQ(device.wrong_positions, 0u) << case_name << ": one-launch positions";
            }
        }
    }
}

TEST(RawTreeEmitDeviceLogic, RandomTreesEqualTheHostEmitter) {
    const SceneGeometry g = mixed_triangles(3000, 5);
    uint32_t seed = 100;
    for (uint32_t max_run : {1u, 4u}) {
        for (bool shuffle_leaves : {false, true}) {
            for (Shape shape : {Shape::kRandom, Shape::kBalanced}) {
                for (int leaf_size : {1, 4, 8}) {
                    BvhBuildConfig config;
                    config.max_leaf_size = std::max<int>(leaf_size, static_cast<int>(max_run));
                    for (uint32_t n : {2u, 3u, 17u, 3000u}) {
                        const RawInput in = random_tree(n, max_run, shuffle_leaves, shape, ++seed);
                        check_against_host(g, config, in, seed,
                                           "n " + std::to_string(n) + " run " + std::to_string(max_run) +
                                               " leaf " + std::to_string(config.max_leaf_size) + " seed " +
                                               std::to_string(seed));
                    }
                }
            }
        }
    }
}

TEST(RawTreeEmitDeviceLogic, CostsOtherThanOneAreRoundedLikeTheHost) {
    const SceneGeometry g = mixed_triangles(2000, 9);
    BvhBuildConfig config;
    config.max_leaf_size = 6;
    config.sah.traversal = 1.3f;
    config.sah.intersection = 0.7f;
    for (uint32_t seed = 1; seed <= 4; ++seed) {
        check_against_host(g, config, random_tree(2000, 3, seed % 2 == 0, Shape::kRandom, seed), seed, "costs");
    }
}

TEST(RawTreeEmitDeviceLogic, DeepTreesAreLeftToTheHost) {
    const SceneGeometry g = mixed_triangles(400, 3);
    BvhBuildConfig config;
    config.max_leaf_size = 2;
    // A chain of 400 single-primitive leaves: emitted height far above 64.
    const RawInput deep = random_tree(400, 1, true, Shape::kChain, 7);
    EXPECT_FALSE(emulate(g.triangles, config, deep, 1).fits);
    EXPECT_TRUE(host_emit(g.triangles, config, deep).needs_rebuild);
    // A chain of 60 fits, and is emitted as the host does.
    check_against_host(g, config, random_tree(60, 1, true, Shape::kChain, 8), 2, "chain of 60");
    check_against_host(g, config, random_tree(70, 1, false, Shape::kChain, 9), 3, "chain of 70");
}

TEST(RawTreeEmitDeviceLogic, KarrasTreesEqualTheLbvhEmission) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    const SceneGeometry soup = mixed_triangles(5000, 21);
    for (const SceneGeometry* g : {&sphere, &soup}) {
        const std::span<const Triangle> tris = g->triangles;
        const uint32_t n = static_cast<uint32_t>(tris.size());
        morton::RawTree sorter(tris, BvhBuildConfig{});
        morton::Buffer<uint64_t> keys;
        sorter.sort_by_morton_codes(keys);
        RawInput in;
        in.order = sorter.order;
        in.children.assign(2 * size_t{n - 1}, kNoChild);
        for (uint32_t i = 0; i + 1 < n; ++i) {
            karras::build_inner(keys.data(), n, i, &in.children[2 * size_t{i}], nullptr, nullptr);
        }
        in.high_base = n - 1;
        in.root = 0;
        for (int leaf_size : {1, 4}) {
            BvhBuildConfig config;
            config.max_leaf_size = leaf_size;
            const Emulated device = emulate(tris, config, in, 77);
            ASSERT_TRUE(device.fits);
            const Bvh expected = emit_karras_tree(tris, config, std::vector<uint32_t>(in.order), in.children);
            EXPECT_TRUE(same_bvh(device.bvh, expected)) << "n " << n << " leaf " << leaf_size;
            EXPECT_TRUE(same_bvh(device.one_launch, expected)) << "n " << n << " leaf " << leaf_size << ", one launch";
        }
    }
}

TEST(RawTreeEmitDeviceLogic, DeliberateBugIsCaught) {
    const SceneGeometry g = mixed_triangles(1000, 4);
    BvhBuildConfig config;
    config.max_leaf_size = 4;
    const RawInput in = random_tree(1000, 1, true, Shape::kRandom, 11);
    const HostEmission host = host_emit(g.triangles, config, in);
    ASSERT_FALSE(host.needs_rebuild);
    const Emulated buggy = emulate<FirstArrivalContinues>(g.triangles, config, in, 5);
    EXPECT_FALSE(buggy.fits && same_bvh(buggy.bvh, host.bvh));
}

using test::bvh_hash;

// The CPU Morton builders now finalize nodes through raw_emit::combine, the
// device emission's own step. Their output is pinned by hashes taken before
// that change, so sharing the step cannot have moved a bit.
// RF_PRINT_MORTON_HASHES=1 prints the hashes (to re-pin after an intended change).
TEST(RawTreeEmitDeviceLogic, CpuMortonBuildersOutputIsPinned) {
    const bool print = std::getenv("RF_PRINT_MORTON_HASHES") != nullptr;
    const std::vector<uint64_t> expected = {
        0x49b09d3fa091310aull,
        0x49b09d3fa091310aull,
        0xe6032acb1284caeaull,
        0xd9ad08bcb899ec72ull,
        0x2ab3fc9c6c62f3a9ull,
        0x2ab3fc9c6c62f3a9ull,
        0x3f9a068887953d84ull,
        0xe007cd535dce7004ull,
        0xf9203fdb05eec9a0ull,
        0xf9203fdb05eec9a0ull,
        0xbc6af1462e98a0d0ull,
        0x4b9be60e8521d327ull,
        0x7d99cc2728b01cb8ull,
        0x7d99cc2728b01cb8ull,
        0x4d5f1cda72a9f9a8ull,
        0x48183000b6bd6ab8ull,
        0x7abab3e6b3a7ffe3ull,
        0x7abab3e6b3a7ffe3ull,
        0x1ad7ac045c3d0a6bull,
        0x4f78cf825572be31ull,
        0xaa0e7ca34058f811ull,
        0xaa0e7ca34058f811ull,
        0x239e3c58adbc9664ull,
        0x2f7f7c685996beaeull,
    };
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    const SceneGeometry soup = mixed_triangles(4000, 13);
    const SceneGeometry nasty = test::make_nasty_geometry(3);
    size_t k = 0;
    for (const SceneGeometry* g : {&sphere, &soup, &nasty}) {
        for (int variant = 0; variant < 2; ++variant) {
            BvhBuildConfig config;
            config.max_leaf_size = variant == 0 ? 4 : 7;
            config.sah.traversal = variant == 0 ? 1.0f : 1.3f;
            config.sah.intersection = variant == 0 ? 1.0f : 0.7f;
            const uint64_t hashes[] = {bvh_hash(build_lbvh(g->triangles, config, 30)),
                                       bvh_hash(build_lbvh(g->triangles, config, 63)),
                                       bvh_hash(build_hlbvh2(g->triangles, config)),
                                       bvh_hash(build_ploc(g->triangles, config, PlocOptions{}))};
            for (uint64_t h : hashes) {
                if (print) std::printf("        0x%016llxull,\n", static_cast<unsigned long long>(h));
                if (k < expected.size()) EXPECT_EQ(expected[k], h) << "hash " << k;
                ++k;
            }
        }
    }
    EXPECT_EQ(k, expected.size());
}

}  // namespace
}  // namespace rf
