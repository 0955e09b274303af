// The per-thread logic of the CUDA LBVH (Karras 2012; src/accel/bvh/builders/
// karras_tree_steps.h) run on the CPU the way the kernels run it: build_inner for
// every inner node independently (with parent links), then the bottom-up box
// pass with one walker per leaf, in shuffled orders and on many std::threads,
// so the "second arrival continues" counter logic is exercised. Checks the
// radix tree against a top-down reference, the boxes against their
// children, the parents, the arrival counts, and that emitting the tree
// (emit_karras_tree, the device build's host half) gives build_lbvh's BVH.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/lbvh.h"
#include "accel/bvh/builders/lbvh_emit.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel_test_scenes.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using karras::kLeafRef;
using karras::kNoParent;

constexpr uint32_t kUnset = 0xdeadbeefu;

bool same_box(const Box3f& a, const Box3f& b) { return std::memcmp(&a, &b, sizeof(Box3f)) == 0; }

// What the device pipeline has after its sort: the stable Morton order, the
// sorted codes and the triangles' boxes (per triangle, as the device keeps them).
template <class Key>
struct SortedInput {
    std::vector<Key> keys;
    std::vector<uint32_t> order;
    std::vector<Box3f> sorted_boxes;     // per sorted position
    std::vector<Box3f> triangle_boxes;   // per triangle
};

template <class Key>
SortedInput<Key> sort_input(std::span<const Triangle> triangles) {
    morton::RawTree tree(triangles, BvhBuildConfig{});
    morton::Buffer<Key> keys;
    tree.sort_by_morton_codes(keys);
    SortedInput<Key> in;
    const uint32_t n = tree.size();
    in.keys.assign(keys.data(), keys.data() + n);
    in.order = tree.order;
    in.sorted_boxes.assign(tree.boxes.data(), tree.boxes.data() + n);
    in.triangle_boxes.resize(n);
    for (uint32_t i = 0; i < n; ++i) in.triangle_boxes[in.order[i]] = in.sorted_boxes[i];
    return in;
}

struct KarrasTree {
    std::vector<uint32_t> children, inner_parent, leaf_parent, arrivals;
    std::vector<Box3f> inner_boxes;
};

// The inner-node kernel: one independent call per node.
template <class Key>
KarrasTree build_inner_nodes(const std::vector<Key>& keys) {
    const uint32_t n = static_cast<uint32_t>(keys.size());
    KarrasTree t;
    t.children.assign(2 * size_t{n - 1}, kUnset);
    t.inner_parent.assign(n - 1, kUnset);
    t.leaf_parent.assign(n, kUnset);
    for (uint32_t i = 0; i + 1 < n; ++i) {
        karras::build_inner(keys.data(), n, i, &t.children[2 * size_t{i}], t.inner_parent.data(), t.leaf_parent.data());
    }
    return t;
}

karras::BoxPassView box_view(KarrasTree& t, const std::vector<Box3f>& boxes, const std::vector<uint32_t>* order) {
    const uint32_t inner = static_cast<uint32_t>(t.inner_parent.size());
    t.arrivals.assign(inner, 0u);
    t.inner_boxes.assign(inner, Box3f{});
    return {t.children.data(), t.inner_parent.data(), t.leaf_parent.data(), boxes.data(),
            order ? order->data() : nullptr, t.inner_boxes.data(), t.arrivals.data()};
}

// The box kernel on one thread, leaves in the given order.
template <class Arrival>
void box_pass_serial(const karras::BoxPassView& view, const std::vector<uint32_t>& leaves) {
    for (uint32_t leaf : leaves) karras::propagate_boxes_from_leaf<Arrival>(view, leaf);
}

// The box kernel on `threads` std::threads taking leaves from a shared queue.
void box_pass_threaded(const karras::BoxPassView& view, const std::vector<uint32_t>& leaves, int threads) {
    std::atomic<size_t> next{0};
    std::vector<std::thread> pool;
    for (int k = 0; k < threads; ++k) {
        pool.emplace_back([&] {
            for (size_t i; (i = next.fetch_add(1)) < leaves.size();) {
                karras::propagate_boxes_from_leaf<karras::AtomicArrival>(view, leaves[i]);
            }
        });
    }
    for (std::thread& th : pool) th.join();
}

std::vector<uint32_t> shuffled_leaves(uint32_t n, uint32_t seed) {
    std::vector<uint32_t> leaves(n);
    std::iota(leaves.begin(), leaves.end(), 0u);
    std::mt19937 rng(seed);
    std::shuffle(leaves.begin(), leaves.end(), rng);
    return leaves;
}

// The binary radix tree of the keys (code ++ position) built top-down by
// linear scans (Karras sec. 3 defines it: a node over [first, last] splits
// where the highest differing bit of its keys changes; the left child is
// numbered by its last position, the right child by its first).
template <class Key>
int common_prefix(const std::vector<Key>& keys, uint32_t a, uint32_t b) {
    if (keys[a] != keys[b]) return std::countl_zero(static_cast<Key>(keys[a] ^ keys[b]));
    return int{sizeof(Key) * 8} + std::countl_zero(a ^ b);
}
template <class Key>
std::vector<uint32_t> reference_children(const std::vector<Key>& keys) {
    const uint32_t n = static_cast<uint32_t>(keys.size());
    std::vector<uint32_t> children(2 * size_t{n - 1}, kUnset);
    auto build = [&](auto&& self, uint32_t index, uint32_t first, uint32_t last) -> void {
        const int node_prefix = common_prefix(keys, first, last);
        uint32_t split = first;
        while (split + 1 < last && common_prefix(keys, first, split + 1) > node_prefix) ++split;
        const uint32_t left = split == first ? kLeafRef | split : split;
        const uint32_t right = split + 1 == last ? kLeafRef | (split + 1) : split + 1;
        children[2 * size_t{index}] = left;
        children[2 * size_t{index} + 1] = right;
        if (!karras::is_leaf_ref(left)) self(self, left, first, split);
        if (!karras::is_leaf_ref(right)) self(self, right, split + 1, last);
    };
    build(build, 0, 0, n - 1);
    return children;
}

// Inner nodes whose box is not exactly the union of its children's (left
// first), counted; plus structural checks of parents and references.
template <class Key>
size_t check_tree(const KarrasTree& t, const SortedInput<Key>& in, bool boxes_done = true) {
    const uint32_t n = static_cast<uint32_t>(in.keys.size());
    const uint32_t inner = n - 1;
    std::vector<int> leaf_refs(n, 0), inner_refs(inner, 0);
    for (uint32_t i = 0; i < inner; ++i) {
        for (int c = 0; c < 2; ++c) {
            const uint32_t ref = t.children[2 * size_t{i} + c];
            if (karras::is_leaf_ref(ref)) {
                const uint32_t leaf = ref & ~kLeafRef;
                EXPECT_LT(leaf, n);
                if (leaf >= n) continue;
                ++leaf_refs[leaf];
                EXPECT_EQ(t.leaf_parent[leaf], i) << "leaf " << leaf;
            } else {
                EXPECT_LT(ref, inner);
                if (ref >= inner) continue;
                ++inner_refs[ref];
                EXPECT_EQ(t.inner_parent[ref], i) << "inner " << ref;
            }
        }
    }
    for (uint32_t leaf = 0; leaf < n; ++leaf) EXPECT_EQ(leaf_refs[leaf], 1) << "leaf " << leaf;
    EXPECT_EQ(inner_refs[0], 0);
    EXPECT_EQ(t.inner_parent[0], kNoParent);
    for (uint32_t i = 1; i < inner; ++i) EXPECT_EQ(inner_refs[i], 1) << "inner " << i;
    if (!boxes_done) return 0;
    size_t wrong = 0;
    auto box_of = [&](uint32_t ref) {
        return karras::is_leaf_ref(ref) ? in.sorted_boxes[ref & ~kLeafRef] : t.inner_boxes[ref];
    };
    for (uint32_t i = 0; i < inner; ++i) {
        const Box3f expected =
            morton::box_union(box_of(t.children[2 * size_t{i}]), box_of(t.children[2 * size_t{i} + 1]));
        wrong += !same_box(expected, t.inner_boxes[i]);
    }
    return wrong;
}

void expect_same_bvh(const Bvh& expected, const Bvh& got, const std::string& what) {
    ASSERT_EQ(expected.nodes.size(), got.nodes.size()) << what;
    EXPECT_EQ(expected.prim_indices, got.prim_indices) << what;
    for (size_t i = 0; i < expected.nodes.size(); ++i) {
        EXPECT_TRUE(same_box(expected.nodes[i].bounds, got.nodes[i].bounds)) << what << " node " << i;
        EXPECT_EQ(expected.nodes[i].first, got.nodes[i].first) << what << " node " << i;
        EXPECT_EQ(expected.nodes[i].count, got.nodes[i].count) << what << " node " << i;
    }
}

// The whole device pipeline emulated on `triangles`, checked at every step.
template <class Key>
void check_pipeline(const SceneGeometry& g, const std::string& what) {
    SCOPED_TRACE(what + (sizeof(Key) == 4 ? " (30-bit)" : " (63-bit)"));
    const int bits = sizeof(Key) == 4 ? 30 : 63;
    const SortedInput<Key> in = sort_input<Key>(g.triangles);
    const uint32_t n = static_cast<uint32_t>(in.keys.size());
    ASSERT_GE(n, 1u);
    std::vector<uint32_t> children;
    if (n >= 2) {
        KarrasTree t = build_inner_nodes(in.keys);
        EXPECT_EQ(t.children, reference_children(in.keys));
        // Leaves in sorted order, reversed, shuffled; boxes per triangle
        // through the order (the device's way) and per sorted position.
        std::vector<uint32_t> forward(n);
        std::iota(forward.begin(), forward.end(), 0u);
        std::vector<uint32_t> backward(forward.rbegin(), forward.rend());
        for (const auto* leaves : {&forward, &backward}) {
            box_pass_serial<karras::AtomicArrival>(box_view(t, in.triangle_boxes, &in.order), *leaves);
            EXPECT_EQ(check_tree(t, in), 0u);
        }
        for (uint32_t seed : {1u, 2u}) {
            box_pass_serial<karras::AtomicArrival>(box_view(t, in.sorted_boxes, nullptr), shuffled_leaves(n, seed));
            EXPECT_EQ(check_tree(t, in), 0u);
            for (uint32_t a : t.arrivals) EXPECT_EQ(a, 2u);
        }
        box_pass_threaded(box_view(t, in.triangle_boxes, &in.order), shuffled_leaves(n, 3), 8);
        EXPECT_EQ(check_tree(t, in), 0u);
        for (uint32_t a : t.arrivals) ASSERT_EQ(a, 2u);
        // The root's box is the box of everything.
        Box3f all = in.sorted_boxes[0];
        for (uint32_t i = 1; i < n; ++i) all = morton::box_union(all, in.sorted_boxes[i]);
        EXPECT_TRUE(same_box(all, t.inner_boxes[0]));
        children = t.children;
    }
    // The device build's host half gives build_lbvh's BVH.
    for (int leaf_size : {1, 4}) {
        const BvhBuildConfig config{.max_leaf_size = leaf_size};
        std::vector<uint32_t> order = in.order;
        expect_same_bvh(build_lbvh(g.triangles, config, bits),
                        emit_karras_tree(g.triangles, config, std::move(order), children),
                        "leaf size " + std::to_string(leaf_size));
    }
}

template <class Key>
void check_all_inputs() {
    check_pipeline<Key>(test::make_triangle_soup(3000, 11, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f), "soup");
    check_pipeline<Key>(test::make_triangle_soup(777, 12, {Vec3f(1e6f), Vec3f(1e6f + 10.0f)}, 0.01f), "far soup");
    check_pipeline<Key>(test::to_geometry(test::make_icosphere(3)), "sphere");
    check_pipeline<Key>(test::make_nasty_geometry(5), "nasty");
    SceneGeometry same;  // every code equal: the tree comes from the positions alone
    for (int i = 0; i < 600; ++i) test::append(same, {Vec3f(2.0f), Vec3f(2.0f), Vec3f(2.0f)});
    check_pipeline<Key>(same, "all in one point");
    SceneGeometry two, one;
    test::append(two, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    test::append(two, {Vec3f(5, 5, 5), Vec3f(6, 5, 5), Vec3f(5, 6, 5)});
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    check_pipeline<Key>(two, "two triangles");
    check_pipeline<Key>(one, "one triangle");
}

TEST(LbvhDeviceLogic, DeltaComparesCodesThenPositions) {
    const uint32_t keys30[4] = {0u, 0u, 1u, 0x20000000u};
    EXPECT_EQ(karras::delta(keys30, 4, 0, 4), -1);
    EXPECT_EQ(karras::delta(keys30, 4, 1, -1), -1);
    EXPECT_EQ(karras::delta(keys30, 4, 0, 1), 32 + 31);  // equal codes: 32 + prefix of positions 0, 1
    EXPECT_EQ(karras::delta(keys30, 4, 1, 2), 31);       // codes 0 and 1 differ in bit 0
    EXPECT_EQ(karras::delta(keys30, 4, 0, 3), 2);        // bit 29 of 32
    const uint64_t keys63[3] = {5ull, 5ull, 1ull << 62};
    EXPECT_EQ(karras::delta(keys63, 3, 0, 1), 64 + 31);
    EXPECT_EQ(karras::delta(keys63, 3, 1, 2), 1);
    EXPECT_EQ(karras::delta(keys63, 3, 2, 3), -1);
}

TEST(LbvhDeviceLogic, PipelineMatchesCpuLbvh30) { check_all_inputs<uint32_t>(); }
TEST(LbvhDeviceLogic, PipelineMatchesCpuLbvh63) { check_all_inputs<uint64_t>(); }

TEST(LbvhDeviceLogic, EmitRejectsMismatchedInput) {
    SceneGeometry two;
    test::append(two, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    test::append(two, {Vec3f(5, 5, 5), Vec3f(6, 5, 5), Vec3f(5, 6, 5)});
    EXPECT_THROW((void)emit_karras_tree(two.triangles, {}, std::vector<uint32_t>{0}, {}), Error);
    EXPECT_THROW((void)emit_karras_tree(two.triangles, {}, std::vector<uint32_t>{0, 1}, {}), Error);
    EXPECT_TRUE(emit_karras_tree({}, {}, {}, {}).nodes.empty());
}

// The bug the counters prevent: if the first thread to arrive went on, it
// would read its sibling's box before the sibling subtree is done (and the
// second arrival, stopping, would never fix it). The checks must see it.
struct FirstArrivalContinues {
    static uint32_t arrive(uint32_t* counter) { return (*counter)++ == 0 ? 1u : 0u; }
};

TEST(LbvhDeviceLogic, FirstArrivalContinuingIsCaught) {
    const SortedInput<uint32_t> in =
        sort_input<uint32_t>(test::make_triangle_soup(2000, 13, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f).triangles);
    const uint32_t n = static_cast<uint32_t>(in.keys.size());
    KarrasTree t = build_inner_nodes(in.keys);
    box_pass_serial<FirstArrivalContinues>(box_view(t, in.triangle_boxes, &in.order), shuffled_leaves(n, 4));
    EXPECT_GT(check_tree(t, in), 0u);
    // The same order with the real counter is right.
    box_pass_serial<karras::AtomicArrival>(box_view(t, in.triangle_boxes, &in.order), shuffled_leaves(n, 4));
    EXPECT_EQ(check_tree(t, in), 0u);
}

TEST(LbvhDeviceLogic, WrongSplitIsCaughtByTheReference) {
    // A corrupted child reference shows up in the reference comparison and
    // the structural checks.
    const SortedInput<uint32_t> in =
        sort_input<uint32_t>(test::make_triangle_soup(500, 14, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f).triangles);
    KarrasTree t = build_inner_nodes(in.keys);
    std::swap(t.children[0], t.children[1]);
    EXPECT_NE(t.children, reference_children(in.keys));
}

}  // namespace
}  // namespace rf
