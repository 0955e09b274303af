// The per-thread logic of the device layout conversions (backend/cuda/
// layout_convert.cu) run on the CPU the way the kernels run it, threads in
// shuffled orders, against the CPU conversions:
//  - Aila-Laine node pairs (aila_laine_steps.h): parent links, subtree sizes
//    bottom up with arrival counters, positions summed over the ancestors,
//    one writer per node; equal to convert_to_aila_laine.
//  - CWBVH (cwbvh_refine_steps.h, cwbvh_collapse_steps.h, cwbvh_emit_steps.h):
//    leaf refinement per canonical node, the section 3 DP bottom up with arrival
//    counters, then the top-down emission level by level (wide-tree
//    discovery, subtree totals, depth-first numbering, encoding); equal to
//    build_cwbvh, with the levels' sizes read on the host per level or kept
//    in records on the device (cwbvh_level_steps.h: one level-order scan
//    over a bound the host knows, steps launched past the last level as the
//    lagged rounds do).
// On BVHs from several builders, a one-leaf BVH, a single triangle and the
// empty BVH; a wrong
// position or a wrong DP decision must fail.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/aila_laine_steps.h"
#include "accel/bvh/layout/cwbvh_collapse_steps.h"
#include "accel/bvh/layout/cwbvh_emit_steps.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "accel/bvh/layout/cwbvh_level_steps.h"
#include "accel/bvh/layout/cwbvh_refine_steps.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"

namespace rf {
namespace {

struct NamedBvh {
    std::string name;
    std::vector<Triangle> triangles;
    Bvh bvh;
};

std::vector<NamedBvh> test_bvhs() {
    std::vector<NamedBvh> out;
    const SceneGeometry soup = test::make_triangle_soup(3000, 7, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.8f);
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    const SceneGeometry nasty = test::make_nasty_geometry(3);
    struct Case {
        const char* name;
        const SceneGeometry* geometry;
        Builder builder;
        int leaf;
    };
    const Case cases[] = {
        {"soup binned", &soup, Builder::BinnedSah, 4},   {"soup sbvh", &soup, Builder::Sbvh, 8},
        {"soup lbvh", &soup, Builder::Lbvh30, 1},        {"sphere sweep", &sphere, Builder::SweepSah, 2},
        {"sphere ploc", &sphere, Builder::Ploc, 4},      {"nasty hlbvh2", &nasty, Builder::Hlbvh2, 4},
        {"nasty gridbvh", &nasty, Builder::GridBvhSplit, 4},
    };
    for (const Case& c : cases) {
        BuildOptions options;
        options.builder = c.builder;
        options.max_leaf_size = c.leaf;
        out.push_back({c.name, c.geometry->triangles, build_bvh(c.geometry->triangles, options)});
    }
    // One leaf of several triangles, and the empty BVH.
    SceneGeometry few;
    for (int i = 0; i < 3; ++i)
        test::append(few, {Vec3f(float(i), 0, 0), Vec3f(float(i) + 1, 0, 0), Vec3f(float(i), 1, float(i))});
    BuildOptions one_leaf;
    one_leaf.max_leaf_size = 8;
    out.push_back({"one leaf", few.triangles, build_bvh(few.triangles, one_leaf)});
    const std::vector<Triangle> single(few.triangles.begin(), few.triangles.begin() + 1);
    out.push_back({"one triangle", single, build_bvh(single, one_leaf)});
    out.push_back({"empty", {}, Bvh{}});
    return out;
}

template <class T>
bool same_bytes(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

// Sequential arrivals: one interleaving of the device's atomics.
struct SequentialArrival {
    static uint32_t arrive(uint32_t* counter) { return (*counter)++; }
};

std::vector<uint32_t> shuffled(uint32_t n, std::mt19937& rng) {
    std::vector<uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    std::shuffle(order.begin(), order.end(), rng);
    return order;
}

// ---- Aila-Laine ----------------------------------------------------------

// The device conversion, thread by thread in shuffled orders; `wrong_turn`
// breaks the position sums (the bug the test must catch).
AilaLaineBvh emulate_aila_laine(const Bvh& bvh, std::span<const Triangle> triangles, uint32_t seed,
                                bool wrong_turn = false) {
    AilaLaineBvh out;
    if (bvh.nodes.empty()) return out;
    out.bounds = bvh.nodes[0].bounds;
    const auto n = static_cast<uint32_t>(bvh.nodes.size());
    const BvhNode* nodes = bvh.nodes.data();
    std::mt19937 rng(seed);
    std::vector<uint32_t> parent(n, aila_laine::kNoParent);
    for (uint32_t i : shuffled(n, rng))
        if (!nodes[i].is_leaf()) aila_laine::parent_links_of(nodes, i, parent.data());
    std::vector<aila_laine::SubtreeSize> size(n);
    std::vector<uint32_t> arrivals(n, 0u);
    for (uint32_t i : shuffled(n, rng))
        if (nodes[i].is_leaf())
            aila_laine::propagate_sizes_from_leaf<SequentialArrival>(nodes, parent.data(), i, size.data(),
                                                                     arrivals.data());
    const aila_laine::SubtreeSize total = size[0];
    out.nodes.resize(total.inner_nodes);
    out.triangles.resize(total.float4s);
    out.leaf_count = total.leaves;
    out.triangle_refs = total.triangle_refs;
    out.root = nodes[0].is_leaf() ? ~int32_t{0} : 0;
    for (uint32_t i : shuffled(n, rng)) {
        aila_laine::Position at = aila_laine::position_of(nodes, parent.data(), size.data(), i);
        if (wrong_turn && !nodes[i].is_leaf() && at.inner_index == 1) at.inner_index = 2;
        if (nodes[i].is_leaf()) {
            aila_laine::write_leaf_list(nodes[i], bvh.prim_indices.data(), triangles.data(),
                                        &out.triangles[at.float4_offset]);
        } else {
            out.nodes[at.inner_index] = aila_laine::node_pair_at(nodes, size.data(), i, at);
        }
    }
    return out;
}

bool same_aila_laine(const AilaLaineBvh& a, const AilaLaineBvh& b) {
    return same_bytes(a.nodes, b.nodes) && same_bytes(a.triangles, b.triangles) && a.root == b.root &&
           std::memcmp(&a.bounds, &b.bounds, sizeof(Box3f)) == 0 && a.leaf_count == b.leaf_count &&
           a.triangle_refs == b.triangle_refs;
}

TEST(LayoutConvertDeviceLogic, AilaLaineEqualsCpuConversion) {
    for (const NamedBvh& c : test_bvhs()) {
        const AilaLaineBvh expected = convert_to_aila_laine(c.bvh, c.triangles);
        for (uint32_t seed : {1u, 2u, 3u}) {
            const AilaLaineBvh got = emulate_aila_laine(c.bvh, c.triangles, seed);
            EXPECT_TRUE(same_aila_laine(expected, got)) << c.name << ", seed " << seed;
        }
    }
}

TEST(LayoutConvertDeviceLogic, AilaLaineWrongPositionFails) {
    const std::vector<NamedBvh> bvhs = test_bvhs();
    const NamedBvh& c = bvhs[0];
    EXPECT_FALSE(same_aila_laine(convert_to_aila_laine(c.bvh, c.triangles),
                                 emulate_aila_laine(c.bvh, c.triangles, 1, true)));
}

// ---- CWBVH ---------------------------------------------------------------

// The first arrival going on instead of the second: parents solved before
// both children are (the bug the DP test must catch).
struct FirstArrival {
    static uint32_t arrive(uint32_t* counter) { return (*counter)++ == 0 ? 1u : 0u; }
};

// The device conversion: refinement per canonical node, the DP by leaf
// threads walking up, then the level-by-level passes of cwbvh_emit_steps.h, every pass's
// threads in a shuffled order.
struct Level {
    uint32_t start, size;
};

// Pass 1 with each level's size on the host (one read per level).
std::vector<Level> discover_levels_on_host(const cwbvh::EmitView& view, std::mt19937& rng) {
    std::vector<Level> levels;
    for (Level level{0, 1}; level.size != 0;) {
        levels.push_back(level);
        for (uint32_t k : shuffled(level.size, rng)) cwbvh::discover(view, level.start + k);
        uint32_t sum = 0;  // the device's exclusive scan
        for (uint32_t k = 0; k < level.size; ++k) {
            view.first_child[level.start + k] = sum;
            sum += view.inner_count[level.start + k];
        }
        const uint32_t next = level.start + level.size;
        for (uint32_t k : shuffled(level.size, rng)) cwbvh::enqueue_children(view, level.start + k, next);
        level = {next, sum};
    }
    return levels;
}

// Pass 1 as layout_convert.cu runs it: level records on the device, grids
// and scans sized by the host's bounds, `overshoot` steps launched after the
// last level (the lagged rounds' copies arrive late); the levels read once
// at the end. `cap`: the wide nodes the arrays hold (inner_count zeroed).
std::vector<Level> discover_levels_by_records(const cwbvh::EmitView& view, uint32_t cap, uint32_t overshoot,
                                              std::mt19937& rng, uint32_t& error) {
    std::vector<cwbvh::LevelRecord> records(kCwbvhMaxDepth + 1, cwbvh::LevelRecord{0, 0});
    records[0] = {0, 1};
    std::vector<uint32_t> prefix(cap);
    uint32_t after_end = 0;
    for (uint32_t step = 0; step < uint32_t(kCwbvhMaxDepth) && after_end <= overshoot; ++step) {
        const uint32_t width = cwbvh::level_width_bound(step, cap);
        for (uint32_t k : shuffled(width, rng)) cwbvh::discover_in_level(view, records.data(), step, k);
        uint32_t sum = 0;  // the device's exclusive scan over the bound, not the level
        for (uint32_t i = 0; i < cwbvh::nodes_through_level_bound(step, cap); ++i) {
            prefix[i] = sum;
            sum += view.inner_count[i];
        }
        cwbvh::next_level_record(prefix.data(), view.inner_count, records.data(), step, cap, &error);
        for (uint32_t k : shuffled(width, rng)) cwbvh::enqueue_in_level(view, records.data(), step, prefix.data(), k);
        if (records[step + 1].count == 0) ++after_end;
    }
    std::vector<Level> levels;
    for (const cwbvh::LevelRecord& r : records) {
        if (r.count == 0) break;
        levels.push_back({r.start, r.count});
    }
    return levels;
}

template <class Arrival = SequentialArrival>
CwbvhBvh emulate_cwbvh(const Bvh& bvh, const std::vector<Triangle>& triangles, uint32_t seed,
                       bool level_records = false) {
    CwbvhBvh out;
    if (bvh.nodes.empty()) return out;
    std::mt19937 rng(seed);
    // 0. Refinement: added node counts, their exclusive scan, one thread per canonical node.
    const auto canonical_count = static_cast<uint32_t>(bvh.nodes.size());
    std::vector<uint32_t> extra_base(canonical_count);
    uint32_t extra = 0;
    for (uint32_t i = 0; i < canonical_count; ++i) {
        extra_base[i] = extra;
        extra += cwbvh::refined_extra(bvh.nodes[i]);
    }
    const uint32_t n = canonical_count + extra;
    std::vector<cwbvh::RefinedNode> refined(n);
    std::vector<cwbvh::RefineRef> scratch(std::max(extra, 1u));
    for (uint32_t i : shuffled(canonical_count, rng))
        cwbvh::refine_node(bvh.nodes.data(), canonical_count, bvh.prim_indices.data(), triangles.data(), i,
                           extra_base[i], scratch.data(), refined.data());
    cwbvh::RefinedNode* nodes = refined.data();
    if constexpr (!std::is_same_v<Arrival, SequentialArrival>) {
        // The broken DP must only get costs wrong: triangle counts are set
        // beforehand so that no leaf slot gets more than three triangles.
        for (uint32_t i = canonical_count; i-- > 0;)
            if (!nodes[i].leaf) nodes[i].triangles = nodes[nodes[i].left].triangles + nodes[nodes[i].left + 1].triangles;
    }

    // 1-2. Parents, the DP.
    std::vector<uint32_t> parent(n, cwbvh::kNoParent);
    for (uint32_t i : shuffled(n, rng))
        if (!nodes[i].leaf) cwbvh::parent_links_of(nodes, i, parent.data());
    const float bias = cwbvh::area_bias(nodes[0].box);
    std::vector<float> cost(size_t{n} * cwbvh::kWidth, 0.0f);
    std::vector<cwbvh::Choice> choices(n, cwbvh::Choice{});
    std::vector<uint32_t> arrivals(n, 0u);
    for (uint32_t i : shuffled(n, rng))
        if (nodes[i].leaf)
            cwbvh::count_and_solve_from_leaf<Arrival>(nodes, parent.data(), i, bias, cost.data(), choices.data(),
                                                      arrivals.data());

    // 3-5. The wide tree level by level.
    std::vector<uint32_t> wide_refined(n), slots(size_t{n} * cwbvh::kWidth), inner_count(n), first_child(n),
        wide_index(n);
    std::vector<cwbvh::OwnCounts> own(n), subtree(n), before(n);
    const size_t triangle_refs = bvh.prim_indices.size();
    out.triangles.resize(triangle_refs);
    out.nodes.resize(n);
    uint32_t leaf_slots = 0, error = 0;
    const cwbvh::EmitView view{nodes,           choices.data(),    triangles.data(), wide_refined.data(),
                               slots.data(),    own.data(),        inner_count.data(), first_child.data(),
                               subtree.data(),  wide_index.data(), before.data(),    out.nodes.data(),
                               out.triangles.data(), &leaf_slots,  &error};
    wide_refined[0] = 0;
    const auto cap = static_cast<uint32_t>(std::clamp<size_t>(triangle_refs, 1, n));  // wide nodes at most
    const std::vector<Level> levels = level_records ? discover_levels_by_records(view, cap, seed % 3, rng, error)
                                                    : discover_levels_on_host(view, rng);
    for (size_t l = levels.size(); l-- > 0;)
        for (uint32_t k : shuffled(levels[l].size, rng)) cwbvh::total(view, levels[l].start + k);
    wide_index[0] = 0;
    before[0] = {0, 0};
    for (const Level& level : levels)
        for (uint32_t k : shuffled(level.size, rng)) cwbvh::emit(view, level.start + k);
    out.nodes.resize(subtree[0].inner + 1u);
    out.leaf_count = leaf_slots;
    out.depth = static_cast<int>(levels.size());
    if (error != 0 || subtree[0].triangles != triangle_refs) out.depth = -1;  // what the device would throw for
    return out;
}

bool same_cwbvh(const CwbvhBvh& a, const CwbvhBvh& b) {
    return same_bytes(a.nodes, b.nodes) && same_bytes(a.triangles, b.triangles) && a.leaf_count == b.leaf_count &&
           a.depth == b.depth;
}

TEST(LayoutConvertDeviceLogic, CwbvhEqualsCpuBuild) {
    for (const NamedBvh& c : test_bvhs()) {
        const CwbvhBvh expected = build_cwbvh(c.bvh, c.triangles);
        for (uint32_t seed : {1u, 2u, 3u}) {
            for (const bool records : {false, true}) {
                const CwbvhBvh got = emulate_cwbvh(c.bvh, c.triangles, seed, records);
                EXPECT_TRUE(same_cwbvh(expected, got))
                    << c.name << ", seed " << seed << (records ? ", level records" : ", host levels") << ": "
                    << expected.nodes.size() << " vs " << got.nodes.size() << " nodes";
            }
        }
    }
}

// The bounds the device's grids and scans use hold for every level.
TEST(LayoutConvertDeviceLogic, LevelBoundsCoverTheLevels) {
    EXPECT_EQ(cwbvh::level_width_bound(0, 100), 1u);
    EXPECT_EQ(cwbvh::level_width_bound(2, 100), 64u);
    EXPECT_EQ(cwbvh::level_width_bound(3, 100), 100u);
    EXPECT_EQ(cwbvh::level_width_bound(40, 0xFFFFFFFFu), 0xFFFFFFFFu);  // no overflow
    EXPECT_EQ(cwbvh::nodes_through_level_bound(0, 100), 1u);
    EXPECT_EQ(cwbvh::nodes_through_level_bound(1, 100), 9u);
    EXPECT_EQ(cwbvh::nodes_through_level_bound(2, 100), 73u);
    EXPECT_EQ(cwbvh::nodes_through_level_bound(3, 100), 100u);
    EXPECT_EQ(cwbvh::nodes_through_level_bound(40, 0xFFFFFFFFu), 0xFFFFFFFFu);
}

// A level past the arrays' capacity is an error, not a write past them.
TEST(LayoutConvertDeviceLogic, LevelRecordPastCapacityFails) {
    const uint32_t prefix[2] = {0, 5}, inner_count[2] = {5, 3};
    cwbvh::LevelRecord records[3] = {{0, 1}, {1, 1}, {0, 0}};
    uint32_t error = 0;
    cwbvh::next_level_record(prefix, inner_count, records, 0, 8, &error);
    EXPECT_EQ(error, 0u);
    EXPECT_EQ(records[1].start, 1u);
    EXPECT_EQ(records[1].count, 5u);
    records[1] = {1, 1};
    cwbvh::next_level_record(prefix, inner_count, records, 1, 8, &error);  // 5 + 3 + 1 = 9 nodes > 8
    EXPECT_EQ(error, cwbvh::kErrorLevelOverflow);
    EXPECT_EQ(records[2].count, 0u);
}

TEST(LayoutConvertDeviceLogic, CwbvhDpSolvedTooEarlyFails) {
    const std::vector<NamedBvh> bvhs = test_bvhs();
    const NamedBvh& c = bvhs[0];
    EXPECT_FALSE(same_cwbvh(build_cwbvh(c.bvh, c.triangles), emulate_cwbvh<FirstArrival>(c.bvh, c.triangles, 1)));
}

}  // namespace
}  // namespace rf

namespace rf {
namespace {

// Unions in different orders may give -0 or +0 for the same bound; the node
// origin must not depend on it, or the device's nodes would differ from the
// CPU's in the sign bit alone.
TEST(LayoutConvertDeviceLogic, QuantisationOriginIgnoresTheSignOfZero) {
    for (const float zero : {0.0f, -0.0f}) {
        Box3f boxes[kCwbvhWidth];
        boxes[0] = {{zero, zero, 1.0f}, {1.0f, 1.0f, 2.0f}};
        boxes[1] = {{0.5f, zero, 1.5f}, {2.0f, 1.0f, 3.0f}};
        CwbvhNode node{};
        ASSERT_TRUE(cwbvh_quantize(node, boxes, 0b11u));
        for (int a = 0; a < 2; ++a) {
            uint32_t bits;
            std::memcpy(&bits, &node.p[a], sizeof bits);
            EXPECT_EQ(bits, 0u) << "axis " << a << ", zero " << (std::signbit(zero) ? "-0" : "+0");
        }
    }
}

}  // namespace
}  // namespace rf
