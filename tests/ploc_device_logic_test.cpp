// The device half of PLOC (Meister and Bittner 2018; backend/cuda/ploc_build.cu)
// checked on the CPU: the shared per-cluster steps of ploc_steps.h run in the
// device's schedule (blocks of clusters with their shared-memory windows,
// blocks and threads in shuffled orders, the atomicMin of the keys as a
// plain minimum, one global exclusive scan per iteration), and the
// clustering handed to emit_ploc_tree must give build_ploc's BVH exactly.
// Also: the 64-bit neighbour key orders candidates as the tie rule does,
// the window search finds the plain search's neighbours, degenerate inputs,
// malformed clusterings are refused, and a deliberate bug is caught.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel_test_scenes.h"
#include "accel/bvh/builders/morton_radix_sort.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel/bvh/builders/ploc.h"
#include "accel/bvh/builders/ploc_emit.h"
#include "accel/bvh/builders/ploc_steps.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

constexpr uint32_t kDeviceBlock = 256;       // ploc_build.cu's kBlockSize
constexpr uint32_t kMaxWindowRadius = 256;   // ploc_build.cu's kMaxWindowRadius

enum class Bug { None, SkipLeftHalo };

struct Clustering {
    std::vector<uint32_t> order;
    std::vector<uint32_t> children;
    std::vector<uint32_t> iteration_nodes;
    std::vector<Box3f> node_boxes;
};

// Cluster i's neighbour in the device's window kernel: the block holding i
// evaluates every pair with an end in the block once, left ends in a
// shuffled order (the threads), keeping the smallest key per cluster (the
// shared atomicMin).
void window_neighbours(const std::vector<Box3f>& boxes, uint32_t count, uint32_t radius, uint32_t block_size,
                       std::mt19937& rng, Bug bug, std::vector<uint32_t>& neighbour) {
    const uint32_t blocks = (count + block_size - 1) / block_size;
    std::vector<uint32_t> block_order(blocks);
    std::iota(block_order.begin(), block_order.end(), 0u);
    std::shuffle(block_order.begin(), block_order.end(), rng);
    for (uint32_t b : block_order) {
        const ploc::Window w = ploc::block_window(b * block_size, block_size, count, radius);
        const std::vector<Box3f> window_boxes(boxes.begin() + w.begin, boxes.begin() + w.end);
        std::vector<uint64_t> keys(block_size, ploc::kNoNeighbour);
        // The bug: the pairs reaching in from the previous block are never evaluated.
        const uint32_t first_left = bug == Bug::SkipLeftHalo ? w.block_begin : w.begin;
        std::vector<uint32_t> lefts(w.block_end - first_left);
        std::iota(lefts.begin(), lefts.end(), first_left);
        std::shuffle(lefts.begin(), lefts.end(), rng);
        auto record = [&](uint32_t slot, uint64_t key) { keys[slot] = std::min(keys[slot], key); };
        for (uint32_t p : lefts) ploc::window_pairs_from(window_boxes.data(), w, radius, p, record);
        for (uint32_t i = w.block_begin; i < w.block_end; ++i) {
            neighbour[i] = ploc::neighbour_from_key(i, keys[i - w.block_begin]);
        }
    }
}

// The device build, kernel by kernel, on the CPU.
Clustering emulate_device(std::span<const Triangle> triangles, int radius_option, uint32_t block_size, uint32_t seed,
                          Bug bug = Bug::None) {
    Clustering out;
    std::vector<uint64_t> codes;
    morton::compute_morton_codes(triangles, codes, out.order);
    const uint32_t n = static_cast<uint32_t>(codes.size());
    if (n == 0) return out;
    radix_sort_pairs(codes, out.order, 63);
    if (n == 1) return out;
    morton::RawTree tree(triangles, BvhBuildConfig{});
    tree.set_order(std::vector<uint32_t>(out.order));

    const uint32_t radius = ploc::clamp_radius(radius_option);
    std::mt19937 rng(seed);
    std::vector<uint32_t> refs[2] = {std::vector<uint32_t>(n), std::vector<uint32_t>(n)};
    std::vector<Box3f> boxes[2] = {std::vector<Box3f>(n), std::vector<Box3f>(n)};
    for (uint32_t i = 0; i < n; ++i) {
        refs[0][i] = ploc::kLeafRef | i;
        boxes[0][i] = tree.boxes[i];
    }
    std::vector<uint32_t> neighbour(n), threads(n + 1);
    std::vector<uint64_t> flags(n + 1), prefix(n + 1);
    out.children.assign(2 * size_t{n - 1}, 0xdeadbeefu);
    out.node_boxes.resize(n - 1);
    uint32_t count = n, next_node = 0;
    int current = 0;
    while (count > 1) {
        auto shuffled = [&](uint32_t size) {
            threads.resize(size);
            std::iota(threads.begin(), threads.end(), 0u);
            std::shuffle(threads.begin(), threads.end(), rng);
            return threads;
        };
        if (radius <= kMaxWindowRadius) {
            window_neighbours(boxes[current], count, radius, block_size, rng, bug, neighbour);
        } else {
            for (uint32_t i : shuffled(count)) neighbour[i] = ploc::nearest_neighbour(boxes[current].data(), count, radius, i);
        }
        for (uint32_t i : shuffled(count + 1)) flags[i] = i < count ? ploc::compaction_flags(neighbour.data(), i) : 0;
        std::exclusive_scan(flags.begin(), flags.begin() + count + 1, prefix.begin(), uint64_t{0});
        const ploc::ClusterArrays arrays{refs[current].data(),     boxes[current].data(), refs[1 - current].data(),
                                         boxes[1 - current].data(), out.children.data(),  out.node_boxes.data()};
        for (uint32_t i : shuffled(count)) ploc::compact_cluster(arrays, neighbour.data(), i, prefix[i], next_node);
        const uint32_t survivors = static_cast<uint32_t>(prefix[count] >> 32);
        const uint32_t merges = static_cast<uint32_t>(prefix[count]);
        if (merges == 0 || survivors != count - merges) throw Error("emulated PLOC made no progress");
        out.iteration_nodes.push_back(merges);
        next_node += merges;
        count = survivors;
        current = 1 - current;
    }
    return out;
}

bool same_bvh(const Bvh& a, const Bvh& b) {
    return a.prim_indices == b.prim_indices && a.nodes.size() == b.nodes.size() &&
           (a.nodes.empty() ||  // memcmp must not see the null data() of empty vectors
            std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(a.nodes[0])) == 0);
}

Bvh emit(std::span<const Triangle> triangles, const BvhBuildConfig& config, Clustering&& c) {
    return emit_ploc_tree(triangles, config, std::move(c.order), c.children, c.iteration_nodes);
}

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(4000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(3))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    SceneGeometry point;  // every triangle in one point: equal codes, equal boxes
    for (int i = 0; i < 700; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    scenes.push_back({"one point", std::move(point)});
    SceneGeometry nested;  // one centre, growing triangles: equal codes, different boxes
    for (int i = 1; i <= 500; ++i) {
        const float s = 0.01f * static_cast<float>(i);
        test::append(nested, {Vec3f(-s, -s, 0), Vec3f(s, -s, 0), Vec3f(0, s, 0)});
    }
    scenes.push_back({"equal codes", std::move(nested)});
    SceneGeometry two;
    test::append(two, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    test::append(two, {Vec3f(0, 0, 2), Vec3f(1, 0, 2), Vec3f(0, 1, 2)});
    scenes.push_back({"two", two});
    SceneGeometry one;
    test::append(one, two.triangles[1]);
    scenes.push_back({"one", std::move(one)});
    scenes.push_back({"empty", SceneGeometry{}});
    return scenes;
}

TEST(PlocDeviceLogic, NeighbourKeyOrdersCandidatesLikeTheTieRule) {
    std::mt19937 rng(3);
    const float areas[] = {0.0f, -0.0f, 1.0f, 1.0f, 2.5f, 1e30f, std::numeric_limits<float>::infinity()};
    size_t checked = 0;
    for (int trial = 0; trial < 20000; ++trial) {
        const uint32_t radius = trial % 3 == 0 ? 1 : trial % 3 == 1 ? 16 : ploc::kMaxRadius;
        const uint32_t i = std::uniform_int_distribution<uint32_t>(radius, 1u << 30)(rng);
        auto candidate = [&] {
            const uint32_t d = std::uniform_int_distribution<uint32_t>(1, std::min(radius, 4u + trial % 40))(rng);
            return rng() & 1 ? i + d : i - d;
        };
        const uint32_t j = candidate(), k = candidate();
        EXPECT_EQ(ploc::neighbour_from_key(i, ploc::neighbour_key(1.0f, i, j)), j);
        if (j == k) continue;
        const float aj = areas[rng() % 7], ak = areas[rng() % 7];
        const bool expected = aj < ak || (aj == ak && ploc::closer_pair(i, j, k));
        ASSERT_EQ(ploc::neighbour_key(aj, i, j) < ploc::neighbour_key(ak, i, k), expected)
            << i << " " << j << " " << k << " " << aj << " " << ak;
        ++checked;
    }
    EXPECT_GT(checked, 15000u);
}

TEST(PlocDeviceLogic, MergedAreaIsSymmetricWithSignedZeros) {
    const Box3f a{Vec3f(-0.0f, 0.0f, 1.0f), Vec3f(0.0f, -0.0f, 2.0f)};
    const Box3f b{Vec3f(0.0f, -0.0f, 1.0f), Vec3f(-0.0f, 0.0f, 3.0f)};
    EXPECT_EQ(ploc::neighbour_key(ploc::merged_area(a, b), 4, 5), ploc::neighbour_key(ploc::merged_area(b, a), 4, 5));
    const Box3f flat{Vec3f(0.0f, -0.0f, 1.0f), Vec3f(0.0f, 0.0f, 1.0f)};
    EXPECT_EQ(ploc::neighbour_key(ploc::merged_area(flat, flat), 4, 5), ploc::neighbour_key(0.0f, 4, 5));
}

TEST(PlocDeviceLogic, WindowSearchFindsThePlainSearchNeighbours) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(0.0f, 10.0f);
    for (uint32_t count : {2u, 3u, 31u, 257u, 1000u}) {
        std::vector<Box3f> boxes(count);
        for (uint32_t i = 0; i < count; ++i) {
            const Vec3f c(u(rng), u(rng), u(rng));
            // A few duplicates, so ties are exercised.
            boxes[i] = i % 7 == 3 ? boxes[i - 1] : Box3f{c, c + Vec3f(u(rng), u(rng), u(rng)) * 0.1f};
        }
        for (uint32_t radius : {1u, 2u, 16u, 100u}) {
            for (uint32_t block_size : {8u, 32u, kDeviceBlock}) {
                std::vector<uint32_t> window(count);
                window_neighbours(boxes, count, radius, block_size, rng, Bug::None, window);
                size_t wrong = 0;
                for (uint32_t i = 0; i < count; ++i) wrong += window[i] != ploc::nearest_neighbour(boxes.data(), count, radius, i);
                EXPECT_EQ(wrong, 0u) << count << " clusters, radius " << radius << ", blocks of " << block_size;
            }
        }
    }
}

TEST(PlocDeviceLogic, WindowEvaluatesEachPairOnce) {
    const uint32_t count = 600, radius = 16, block_size = 64;
    std::vector<Box3f> boxes(count, Box3f{Vec3f(0.0f), Vec3f(1.0f)});
    for (uint32_t b = 0; b * block_size < count; ++b) {
        const ploc::Window w = ploc::block_window(b * block_size, block_size, count, radius);
        std::vector<uint32_t> offers(size_t{count} * count, 0);
        for (uint32_t p = w.begin; p < w.block_end; ++p) {
            auto record = [&](uint32_t slot, uint64_t key) {
                const uint32_t i = w.block_begin + slot;
                ++offers[size_t{i} * count + ploc::neighbour_from_key(i, key)];
            };
            ploc::window_pairs_from(boxes.data() + w.begin, w, radius, p, record);
        }
        for (uint32_t i = w.block_begin; i < w.block_end; ++i) {
            for (uint32_t j = 0; j < count; ++j) {
                const uint32_t d = i > j ? i - j : j - i;
                ASSERT_EQ(offers[size_t{i} * count + j], d >= 1 && d <= radius ? 1u : 0u) << i << " " << j;
            }
        }
    }
}

// The clustering does not depend on the leaf size (only the emission does),
// nor, for radii beyond the window, on the block size.
void check_emulation(int radius, std::initializer_list<uint32_t> block_sizes, size_t max_triangles = SIZE_MAX) {
    for (const NamedScene& scene : test_scenes()) {
        if (scene.geometry.triangles.size() > max_triangles) continue;
        for (uint32_t block_size : block_sizes) {
            const Clustering c = emulate_device(scene.geometry.triangles, radius, block_size, 7 + block_size);
            for (int leaf_size : {1, 4}) {
                const BvhBuildConfig config{.max_leaf_size = leaf_size};
                const std::string what = scene.name + ", radius " + std::to_string(radius) + ", leaves of " +
                                         std::to_string(leaf_size) + ", blocks of " + std::to_string(block_size);
                EXPECT_TRUE(same_bvh(build_ploc(scene.geometry.triangles, config, PlocOptions{.radius = radius}),
                                     emit(scene.geometry.triangles, config, Clustering(c))))
                    << what;
            }
        }
    }
}

TEST(PlocDeviceLogic, EmulatedDeviceBuildEqualsCpuPlocRadius1) { check_emulation(1, {32u, kDeviceBlock}); }
TEST(PlocDeviceLogic, EmulatedDeviceBuildEqualsCpuPlocRadius16) { check_emulation(16, {32u, kDeviceBlock}); }
// Beyond kMaxWindowRadius: the plain per-cluster search (smaller scenes: it is slow).
TEST(PlocDeviceLogic, EmulatedDeviceBuildEqualsCpuPlocLargeRadius) { check_emulation(260, {kDeviceBlock}, 1500); }

TEST(PlocDeviceLogic, NodeBoxesAreTheUnionsOfTheirChildren) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 5, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.4f);
    const Clustering c = emulate_device(soup.triangles, 16, kDeviceBlock, 1);
    morton::RawTree tree(soup.triangles, BvhBuildConfig{});
    tree.set_order(std::vector<uint32_t>(c.order));
    const uint32_t n = tree.size();
    ASSERT_EQ(c.node_boxes.size(), n - 1);
    size_t wrong = 0;
    for (uint32_t k = 0; k + 1 < n; ++k) {
        Box3f child[2];
        for (int s = 0; s < 2; ++s) {
            const uint32_t ref = c.children[2 * size_t{k} + s];
            child[s] = morton::is_leaf_ref(ref) ? tree.boxes[ref & ~ploc::kLeafRef] : c.node_boxes[ref];
        }
        const Box3f u = morton::box_union(child[0], child[1]);
        wrong += std::memcmp(&u, &c.node_boxes[k], sizeof(Box3f)) != 0;
    }
    EXPECT_EQ(wrong, 0u);
    uint32_t total = 0;
    for (uint32_t nodes : c.iteration_nodes) total += nodes;
    EXPECT_EQ(total, n - 1);
}

TEST(PlocDeviceLogic, MalformedClusteringsAreRefused) {
    const SceneGeometry soup = test::make_triangle_soup(100, 2, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.4f);
    const Clustering good = emulate_device(soup.triangles, 16, kDeviceBlock, 1);
    auto emit_copy = [&](Clustering c) { return emit(soup.triangles, BvhBuildConfig{}, std::move(c)); };
    EXPECT_TRUE(same_bvh(build_ploc(soup.triangles, {}, {}), emit_copy(good)));
    Clustering twice = good;
    twice.children[1] = twice.children[0];
    EXPECT_THROW((void)emit_copy(twice), Error);
    Clustering future = good;
    future.children[0] = 50;  // a node of a later iteration
    EXPECT_THROW((void)emit_copy(future), Error);
    Clustering short_count = good;
    short_count.iteration_nodes.back() -= 1;
    EXPECT_THROW((void)emit_copy(short_count), Error);
    Clustering outside = good;
    outside.children[0] = ploc::kLeafRef | 100u;
    EXPECT_THROW((void)emit_copy(outside), Error);
}

// The tests can fail: a window kernel that skips the pairs reaching in from
// the previous block misses some left neighbours and builds another tree.
TEST(PlocDeviceLogic, DeliberateBugIsCaught) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 9, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.4f);
    const BvhBuildConfig config{};
    Clustering c = emulate_device(soup.triangles, 16, kDeviceBlock, 2, Bug::SkipLeftHalo);
    EXPECT_FALSE(
        same_bvh(build_ploc(soup.triangles, config, PlocOptions{}), emit(soup.triangles, config, std::move(c))));
}

}  // namespace
}  // namespace rf
