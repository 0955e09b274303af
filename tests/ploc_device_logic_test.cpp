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

// The device loop of ploc_build.cu without host round trips, kernel by
// kernel on the CPU: the loop state on the "device" (two slots, an
// iteration reads one and advances the other), the host's rounds sized by a
// lagging look at the state, grid iterations whose blocks read the count
// (idle past it, no-ops once the tail's turn has come), the flags' prefix
// sum in three passes (block sums, one block scanning them in per-thread
// chunks, per-block scans plus offsets), then the single-block tail with
// its shared arrays, whole-array window and per-thread chunks.
struct LoopSchedule {
    uint32_t block_size = kDeviceBlock;
    uint32_t scan_threads = 1024;
    uint32_t tail_capacity = 3072;
    uint32_t tail_threads = 1024;
    uint32_t iterations_per_round = 3;
};

enum class LoopBug { None, StridedTailChunks };

struct LoopReplay {
    const LoopSchedule& schedule;
    uint32_t radius;
    std::mt19937& rng;
    std::vector<uint32_t> refs[2];
    std::vector<Box3f> boxes[2];
    std::vector<uint32_t> neighbour;
    std::vector<uint64_t> block_sums;
    ploc::LoopState states[2];
    Clustering& out;

    std::vector<uint32_t> shuffled(uint32_t begin, uint32_t end) {
        std::vector<uint32_t> v(end - begin);
        std::iota(v.begin(), v.end(), begin);
        std::shuffle(v.begin(), v.end(), rng);
        return v;
    }

    // Launch `launched` of the grid phase, grids for `bound` clusters.
    void grid_iteration(uint32_t launched, uint32_t bound) {
        const ploc::LoopState s = states[launched & 1];
        ploc::LoopState& next = states[(launched + 1) & 1];
        const uint32_t tail = schedule.tail_capacity, bs = schedule.block_size;
        const uint32_t blocks = (bound + bs - 1) / bs;
        if (!ploc::grid_iteration_runs(s, tail)) {  // every block idle; the scan block passes the state on
            next = s;
            return;
        }
        const uint32_t side = s.iterations & 1u;
        ASSERT_LE(s.count, bound) << "the host's bound is not an upper bound";
        if (radius <= kMaxWindowRadius) {
            window_neighbours(boxes[side], s.count, radius, bs, rng, Bug::None, neighbour);
        } else {
            for (uint32_t i : shuffled(0, s.count)) neighbour[i] = ploc::nearest_neighbour(boxes[side].data(), s.count, radius, i);
        }
        for (uint32_t b : shuffled(0, blocks)) {  // block sums; blocks past the count are idle
            if (b * bs >= s.count) continue;
            uint64_t sum = 0;
            for (uint32_t i = b * bs; i < std::min(s.count, (b + 1) * bs); ++i) sum += ploc::compaction_flags(neighbour.data(), i);
            block_sums[b] = sum;
        }
        // The one scan block: thread chunks, their exclusive scan, in-place offsets.
        const uint32_t used = (s.count + bs - 1) / bs;
        std::vector<uint64_t> thread_sums(schedule.scan_threads, 0), thread_offsets(schedule.scan_threads);
        for (uint32_t t = 0; t < schedule.scan_threads; ++t) {
            const ploc::Chunk c = ploc::thread_chunk(used, schedule.scan_threads, t);
            for (uint32_t b = c.begin; b < c.end; ++b) thread_sums[t] += block_sums[b];
        }
        std::exclusive_scan(thread_sums.begin(), thread_sums.end(), thread_offsets.begin(), uint64_t{0});
        const uint64_t total = thread_offsets.back() + thread_sums.back();
        for (uint32_t t : shuffled(0, schedule.scan_threads)) {
            const ploc::Chunk c = ploc::thread_chunk(used, schedule.scan_threads, t);
            uint64_t offset = thread_offsets[t];
            for (uint32_t b = c.begin; b < c.end; ++b) {
                const uint64_t own = block_sums[b];
                block_sums[b] = offset;
                offset += own;
            }
        }
        next = ploc::commit_iteration(s, total, out.iteration_nodes.data());
        // Compaction: per block, its own exclusive scan plus its offset.
        const ploc::ClusterArrays arrays{refs[side].data(),     boxes[side].data(), refs[1 - side].data(),
                                         boxes[1 - side].data(), out.children.data(), out.node_boxes.data()};
        for (uint32_t b : shuffled(0, blocks)) {
            if (b * bs >= s.count) continue;
            uint64_t local = 0;
            for (uint32_t i = b * bs; i < std::min(s.count, (b + 1) * bs); ++i) {
                ploc::compact_cluster(arrays, neighbour.data(), i, block_sums[b] + local, s.next_node);
                local += ploc::compaction_flags(neighbour.data(), i);
            }
        }
    }

    // The host's rounds: returns the iterations launched.
    uint32_t grid_phase(uint32_t n) {
        uint32_t launched = 0, bound = n;
        std::vector<ploc::LoopState> seen;
        for (uint32_t round = 0;; ++round) {
            for (uint32_t k = 0; k < schedule.iterations_per_round; ++k, ++launched) {
                grid_iteration(launched, bound);
                if (testing::Test::HasFatalFailure()) return launched;
            }
            seen.push_back(states[launched & 1]);
            if (round == 0) continue;
            const ploc::LoopState before = seen[round - 1];
            if (!ploc::grid_iteration_runs(before, schedule.tail_capacity)) return launched;
            bound = before.count;
        }
    }

    // The single-block tail over at most tail_capacity clusters.
    ploc::LoopState tail(const ploc::LoopState& start, LoopBug bug) {
        ploc::LoopState s = ploc::tail_start(start, schedule.tail_capacity);
        if (s.fault != 0) return s;
        const uint32_t from = s.iterations & 1u, threads = schedule.tail_threads;
        std::vector<uint32_t> shared_refs[2] = {std::vector<uint32_t>(refs[from].begin(), refs[from].begin() + s.count),
                                                std::vector<uint32_t>(s.count)};
        std::vector<Box3f> shared_boxes[2] = {std::vector<Box3f>(boxes[from].begin(), boxes[from].begin() + s.count),
                                              std::vector<Box3f>(s.count)};
        std::vector<uint32_t> shared_neighbour(s.count);
        std::vector<uint64_t> thread_sums(threads), thread_prefix(threads);
        for (uint32_t side = 0; s.count > 1; side ^= 1u) {
            const uint32_t count = s.count;
            window_neighbours(shared_boxes[side], count, radius, count, rng, Bug::None, shared_neighbour);
            // Thread t's clusters, in order: its chunk (the bug: every threads-th cluster from t).
            auto for_each_of = [&](uint32_t t, auto&& f) {
                if (bug == LoopBug::StridedTailChunks) {
                    for (uint32_t i = t; i < count; i += threads) f(i);
                    return;
                }
                const ploc::Chunk c = ploc::thread_chunk(count, threads, t);
                for (uint32_t i = c.begin; i < c.end; ++i) f(i);
            };
            for (uint32_t t = 0; t < threads; ++t) {
                thread_sums[t] = 0;
                for_each_of(t, [&](uint32_t i) { thread_sums[t] += ploc::compaction_flags(shared_neighbour.data(), i); });
            }
            std::exclusive_scan(thread_sums.begin(), thread_sums.end(), thread_prefix.begin(), uint64_t{0});
            const uint64_t total = thread_prefix.back() + thread_sums.back();
            const ploc::ClusterArrays arrays{shared_refs[side].data(),     shared_boxes[side].data(),
                                             shared_refs[1 - side].data(), shared_boxes[1 - side].data(),
                                             out.children.data(),          out.node_boxes.data()};
            for (uint32_t t : shuffled(0, threads)) {
                uint64_t prefix = thread_prefix[t];
                for_each_of(t, [&](uint32_t i) {
                    ploc::compact_cluster(arrays, shared_neighbour.data(), i, prefix, s.next_node);
                    prefix += ploc::compaction_flags(shared_neighbour.data(), i);
                });
            }
            s = ploc::commit_iteration(s, total, out.iteration_nodes.data());
            if (s.fault != 0) break;
        }
        return s;
    }
};

// The whole device loop replayed; the final state in *last.
Clustering emulate_device_loop(std::span<const Triangle> triangles, int radius_option, const LoopSchedule& schedule,
                               uint32_t seed, LoopBug bug = LoopBug::None, ploc::LoopState* last = nullptr) {
    Clustering out;
    std::vector<uint64_t> codes;
    morton::compute_morton_codes(triangles, codes, out.order);
    const uint32_t n = static_cast<uint32_t>(codes.size());
    if (n == 0) return out;
    radix_sort_pairs(codes, out.order, 63);
    if (n == 1) return out;
    morton::RawTree tree(triangles, BvhBuildConfig{});
    tree.set_order(std::vector<uint32_t>(out.order));
    std::mt19937 rng(seed);
    out.children.assign(2 * size_t{n - 1}, 0xdeadbeefu);
    out.node_boxes.resize(n - 1);
    out.iteration_nodes.assign(n - 1, 0);
    LoopReplay replay{schedule, ploc::clamp_radius(radius_option), rng, {}, {}, {}, {}, {}, out};
    for (int side = 0; side < 2; ++side) {
        replay.refs[side].resize(n);
        replay.boxes[side].resize(n);
    }
    for (uint32_t i = 0; i < n; ++i) {
        replay.refs[0][i] = ploc::kLeafRef | i;
        replay.boxes[0][i] = tree.boxes[i];
    }
    replay.neighbour.resize(n);
    replay.block_sums.resize((n + schedule.block_size - 1) / schedule.block_size);
    replay.states[0] = ploc::first_state(n);
    const uint32_t launched = n > schedule.tail_capacity ? replay.grid_phase(n) : 0;
    const ploc::LoopState final_state = replay.tail(replay.states[launched & 1], bug);
    if (last != nullptr) *last = final_state;
    out.iteration_nodes.resize(final_state.iterations);
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

// The device loop without host round trips (grid rounds, then the
// single-block tail) makes the per-iteration-scan emulation's clustering
// node for node, and so the CPU PLOC's BVH, for tails that take everything,
// part or (nearly) nothing, small and large thread counts and rounds.
TEST(PlocDeviceLogic, DeviceLoopWithSingleBlockTailEqualsCpuPloc) {
    const LoopSchedule schedules[] = {
        {},                                                   // the device's: small scenes are all tail
        {.block_size = 32, .scan_threads = 8, .tail_capacity = 300, .tail_threads = 64, .iterations_per_round = 3},
        {.block_size = 32, .scan_threads = 3, .tail_capacity = 40, .tail_threads = 1024, .iterations_per_round = 1},
        {.block_size = kDeviceBlock, .scan_threads = 1024, .tail_capacity = 2, .tail_threads = 7, .iterations_per_round = 2},
    };
    size_t checked = 0;
    for (const NamedScene& scene : test_scenes()) {
        for (int radius : {1, 16, 260}) {
            if (radius == 260 && scene.geometry.triangles.size() > 1500) continue;
            const Clustering reference = emulate_device(scene.geometry.triangles, radius, kDeviceBlock, 5);
            for (size_t k = 0; k < std::size(schedules); ++k) {
                const std::string what = scene.name + ", radius " + std::to_string(radius) + ", schedule " + std::to_string(k);
                ploc::LoopState last{};
                const Clustering c = emulate_device_loop(scene.geometry.triangles, radius, schedules[k], 11 + k,
                                                         LoopBug::None, &last);
                ASSERT_FALSE(testing::Test::HasFatalFailure()) << what;
                EXPECT_EQ(c.children, reference.children) << what;
                EXPECT_EQ(c.iteration_nodes, reference.iteration_nodes) << what;
                if (scene.geometry.triangles.size() >= 2) {
                    EXPECT_EQ(last.fault, 0u) << what;
                    EXPECT_EQ(last.count, 1u) << what;
                    EXPECT_EQ(last.next_node, scene.geometry.triangles.size() - 1) << what;
                    EXPECT_EQ(std::memcmp(c.node_boxes.data(), reference.node_boxes.data(),
                                          c.node_boxes.size() * sizeof(Box3f)), 0) << what;
                }
                for (int leaf_size : {1, 4}) {
                    const BvhBuildConfig config{.max_leaf_size = leaf_size};
                    EXPECT_TRUE(same_bvh(build_ploc(scene.geometry.triangles, config, PlocOptions{.radius = radius}),
                                         emit(scene.geometry.triangles, config, Clustering(c))))
                        << what << ", leaves of " << leaf_size;
                }
                ++checked;
            }
        }
    }
    EXPECT_GT(checked, 60u);
}

// The loop state: progress advances it, an iteration without merges or
// with survivors that do not add up faults it (and stops the grid phase and
// the tail), an oversized tail is refused, chunks cover the clusters once.
TEST(PlocDeviceLogic, LoopStateFaultsInsteadOfSpinning) {
    const ploc::LoopState s = ploc::first_state(10);
    uint32_t nodes[4] = {};
    const ploc::LoopState good = ploc::commit_iteration(s, (uint64_t{7} << 32) | 3, nodes);
    EXPECT_EQ(good.count, 7u);
    EXPECT_EQ(good.next_node, 3u);
    EXPECT_EQ(good.iterations, 1u);
    EXPECT_EQ(nodes[0], 3u);
    const ploc::LoopState stuck = ploc::commit_iteration(good, uint64_t{7} << 32, nodes);
    EXPECT_EQ(stuck.fault, ploc::kFaultNoProgress);
    EXPECT_EQ(stuck.iterations, 1u);
    EXPECT_EQ(nodes[1], 0u);
    EXPECT_FALSE(ploc::grid_iteration_runs(stuck, 2));
    EXPECT_EQ(ploc::tail_start(stuck, 100).fault, ploc::kFaultNoProgress);
    EXPECT_EQ(ploc::commit_iteration(good, (uint64_t{5} << 32) | 1, nullptr).fault, ploc::kFaultNoProgress);
    EXPECT_TRUE(ploc::grid_iteration_runs(good, 6));
    EXPECT_FALSE(ploc::grid_iteration_runs(good, 7));
    const ploc::LoopState overflow = ploc::tail_start(good, 6);
    EXPECT_EQ(overflow.fault, ploc::kFaultTailOverflow);
    EXPECT_EQ(overflow.fault_survivors, 7u);
    EXPECT_EQ(ploc::tail_start(good, 7).fault, 0u);
    for (uint32_t count : {0u, 1u, 5u, 1024u, 1025u, 3072u, 100000u}) {
        for (uint32_t threads : {1u, 7u, 1024u}) {
            uint32_t next = 0;
            for (uint32_t t = 0; t < threads; ++t) {
                const ploc::Chunk c = ploc::thread_chunk(count, threads, t);
                ASSERT_EQ(c.begin, next) << count << " " << threads << " " << t;
                ASSERT_LE(c.begin, c.end);
                next = c.end;
            }
            EXPECT_EQ(next, count) << count << " " << threads;
        }
    }
}

// The tail's scan must run over contiguous chunks: strided ones (every
// cluster still counted once) number the nodes and positions out of
// cluster order and build another tree.
TEST(PlocDeviceLogic, DeliberateTailChunkBugIsCaught) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 9, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.4f);
    const LoopSchedule schedule{.tail_capacity = 500, .tail_threads = 64};
    ploc::LoopState last{};
    Clustering c = emulate_device_loop(soup.triangles, 16, schedule, 3, LoopBug::StridedTailChunks, &last);
    EXPECT_EQ(last.fault, 0u);  // the counts still add up ...
    EXPECT_FALSE(same_bvh(build_ploc(soup.triangles, {}, PlocOptions{}),  // ... the tree is another
                          emit(soup.triangles, {}, std::move(c))));
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
