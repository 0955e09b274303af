// The per-task logic of the CUDA HLBVH2 (Garanzha 2014 ch. 5; src/accel/bvh/
// build/hlbvh2_tasks.h) run on the CPU the way the kernels run it: one
// launch per level, each "warp" dequeuing 32 tasks at once from the input
// queue, its lanes splitting with process_task, new tasks placed by the
// warp-local prefix sum (enqueue_offset) after one add on the output tail,
// queues ping-pong; warps are scheduled in a shuffled order. Checks the
// forest against an independent top-down reference (same node indices, same
// children), that every primitive is in exactly one leaf, the level-wise
// bottom-up boxes, and that the host emission (emit_hlbvh2_forest, the
// device build's host half) gives build_hlbvh2's BVH. A wrong split must fail.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel/bvh/build/hlbvh2.h"
#include "accel/bvh/build/hlbvh2_emit.h"
#include "accel/bvh/build/hlbvh2_tasks.h"
#include "accel/bvh/build/morton_tree.h"
#include "accel_test_scenes.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using hlbvh2::kLeafRef;
using hlbvh2::Task;

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
    morton::RawTree tree(triangles, BuildOptions{});
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

// A task step with the split moved one position right where possible: the bug the checks must catch.
uint32_t process_task_wrong_split(const uint32_t* codes, const Task& task, uint32_t leaf_size, uint32_t* refs,
                                  uint8_t* leaf_runs, Task* inner_children, uint32_t* node) {
    const uint32_t inner = hlbvh2::process_task(codes, task, leaf_size, refs, leaf_runs, inner_children, node);
    if (*node == hlbvh2::kNoNode) return inner;
    const uint32_t mid = *node + 2;  // the right split is *node + 1
    if (mid >= task.end) return inner;
    // Redo the node with mid + 1.
    const uint32_t index = mid - 1;
    refs[task.slot] = index;
    *node = index;
    const Task halves[2] = {{task.first, mid, 2 * index}, {mid, task.end, 2 * index + 1}};
    uint32_t count = 0;
    for (const Task& h : halves) {
        if (h.end - h.first <= leaf_size) {
            refs[h.slot] = kLeafRef | h.first;
            leaf_runs[h.first] = static_cast<uint8_t>(h.end - h.first);
        } else {
            inner_children[count++] = h;
        }
    }
    return count;
}

using ProcessTask = uint32_t (*)(const uint32_t*, const Task&, uint32_t, uint32_t*, uint8_t*, Task*, uint32_t*);

struct QueueForest {
    std::vector<uint32_t> refs;
    std::vector<uint8_t> leaf_runs;
    std::vector<std::vector<uint32_t>> level_nodes;  // per level, one entry per task (kNoNode for leaves)
    std::vector<uint32_t> level_sizes;
};

// The work-queue kernels, level by level, warps in a shuffled order.
QueueForest run_work_queues(const SortedClusters& s, uint32_t leaf_size, uint32_t seed,
                            ProcessTask process = hlbvh2::process_task) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const uint32_t clusters = static_cast<uint32_t>(s.cluster_prefix.size());
    QueueForest f;
    f.refs.assign(2 * size_t{n - 1} + clusters, kUnset);
    f.leaf_runs.assign(n, 0);
    std::vector<Task> queue[2];
    for (uint32_t c = 0; c < clusters; ++c) {
        queue[0].push_back({s.cluster_begin[c], s.cluster_begin[c + 1], 2 * (n - 1) + c});  // level 0: the clusters
    }
    std::mt19937 rng(seed);
    int in = 0;
    while (!queue[in].empty()) {
        const std::vector<Task>& input = queue[in];
        std::vector<Task>& output = queue[1 - in];
        output.assign(2 * input.size(), Task{kUnset, kUnset, kUnset});
        uint32_t tail = 0;  // the output queue's atomic counter
        std::vector<uint32_t> nodes(input.size(), kUnset);
        // Warps dequeue 32 tasks each (one add on the head); which warp gets
        // which chunk is up to the hardware: shuffle.
        std::vector<uint32_t> chunks((input.size() + kWarp - 1) / kWarp);
        std::iota(chunks.begin(), chunks.end(), 0u);
        std::shuffle(chunks.begin(), chunks.end(), rng);
        for (uint32_t chunk : chunks) {
            Task children[kWarp][2];
            uint32_t counts[kWarp] = {};
            uint32_t one_or_more = 0, two = 0;
            for (uint32_t lane = 0; lane < kWarp; ++lane) {
                const size_t at = size_t{chunk} * kWarp + lane;
                if (at >= input.size()) continue;
                counts[lane] = process(s.keys.data(), input[at], leaf_size, f.refs.data(), f.leaf_runs.data(),
                                       children[lane], &nodes[at]);
                one_or_more |= (counts[lane] >= 1 ? 1u : 0u) << lane;
                two |= (counts[lane] == 2 ? 1u : 0u) << lane;
            }
            const uint32_t base = tail;  // lane 0's atomicAdd
            tail += hlbvh2::enqueue_total(one_or_more, two);
            for (uint32_t lane = 0; lane < kWarp; ++lane) {
                const uint32_t offset = hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(lane));
                for (uint32_t k = 0; k < counts[lane]; ++k) output[base + offset + k] = children[lane][k];
            }
        }
        output.resize(tail);
        f.level_sizes.push_back(static_cast<uint32_t>(input.size()));
        f.level_nodes.push_back(std::move(nodes));
        queue[in].clear();
        in = 1 - in;
    }
    return f;
}

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

Hlbvh2Forest to_forest(const SortedClusters& s, const QueueForest& f) {
    return {s.order, f.refs, s.cluster_begin, s.cluster_prefix};
}

bool same_bvh(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() && a.prim_indices == b.prim_indices &&
           std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(a.nodes[0])) == 0;
}

TEST(Hlbvh2DeviceLogic, WorkQueuesBuildTheCpuBottomTrees) {
    for (const NamedScene& scene : scenes()) {
        for (uint32_t leaf_size : {1u, 4u}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            const uint32_t n = static_cast<uint32_t>(s.keys.size());
            const uint32_t clusters = static_cast<uint32_t>(s.cluster_prefix.size());
            std::vector<uint32_t> expected(2 * size_t{n - 1} + clusters, kUnset);
            for (uint32_t c = 0; c < clusters; ++c) {
                reference_range(s.keys, s.cluster_begin[c], s.cluster_begin[c + 1], 2 * (n - 1) + c, leaf_size,
                                expected);
            }
            for (uint32_t seed : {1u, 2u}) {
                const QueueForest f = run_work_queues(s, leaf_size, seed);
                std::vector<uint32_t> seen(n, 0);
                size_t wrong = 0;
                for (uint32_t c = 0; c < clusters; ++c) {
                    const uint32_t slot = 2 * (n - 1) + c;
                    wrong += f.refs[slot] != expected[slot];
                    walk(f.refs, f.leaf_runs, expected, f.refs[slot], seen, wrong);
                }
                EXPECT_EQ(wrong, 0u) << "references that differ from the reference";
                EXPECT_EQ(std::count(seen.begin(), seen.end(), 1u), static_cast<long>(n)) << "primitives not in exactly one leaf";
                EXPECT_EQ(f.level_sizes.front(), clusters);
                // Level l >= 1 holds only inner tasks, each a distinct node.
                size_t inner = 0;
                for (const auto& level : f.level_nodes) {
                    inner += std::count_if(level.begin(), level.end(), [](uint32_t v) { return v != hlbvh2::kNoNode; });
                }
                const size_t expected_inner = std::count_if(expected.begin(), expected.end(), [](uint32_t r) {
                    return r != kUnset && (r & kLeafRef) == 0;
                });
                EXPECT_EQ(inner, expected_inner);
            }
        }
    }
}

TEST(Hlbvh2DeviceLogic, LevelWiseBoxesAreUnionsOfChildren) {
    const SortedClusters s = sort_and_cluster(test::make_triangle_soup(5000, 3, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.1f).triangles);
    const QueueForest f = run_work_queues(s, 4, 7);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    Box3f poison;
    poison.lo = Vec3f(1e30f);
    poison.hi = Vec3f(-1e30f);
    std::vector<Box3f> inner_boxes(n - 1, poison);
    const hlbvh2::BoxView view{f.refs.data(), f.leaf_runs.data(), s.order.data(), s.triangle_boxes.data(),
                               inner_boxes.data()};
    for (size_t l = f.level_nodes.size(); l-- > 0;) {  // deepest level first, one launch each
        for (uint32_t node : f.level_nodes[l]) {
            if (node != hlbvh2::kNoNode) hlbvh2::node_box(view, node);
        }
    }
    // Against the boxes of the primitives below each cluster root.
    size_t wrong = 0;
    for (size_t c = 0; c + 1 < s.cluster_begin.size(); ++c) {
        Box3f expected = s.triangle_boxes[s.order[s.cluster_begin[c]]];
        for (uint32_t i = s.cluster_begin[c]; i < s.cluster_begin[c + 1]; ++i) {
            expected = hlbvh2::box_union(expected, s.triangle_boxes[s.order[i]]);
        }
        wrong += !same_box(hlbvh2::reference_box(view, f.refs[2 * (n - 1) + c]), expected);
    }
    EXPECT_EQ(wrong, 0u);
}

TEST(Hlbvh2DeviceLogic, HostEmissionIsBuildHlbvh2) {
    for (const NamedScene& scene : scenes()) {
        for (int leaf_size : {1, 4, 8}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const BuildOptions options{.max_leaf_size = leaf_size};
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            const QueueForest f = run_work_queues(s, static_cast<uint32_t>(leaf_size), 11);
            Hlbvh2Stages stages;
            const Bvh got = emit_hlbvh2_forest(scene.geometry.triangles, options, to_forest(s, f), &stages);
            EXPECT_TRUE(same_bvh(build_hlbvh2(scene.geometry.triangles, options), got));
        }
    }
    EXPECT_TRUE(emit_hlbvh2_forest({}, {}, Hlbvh2Forest{}).nodes.empty());
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
    const BuildOptions options{.max_leaf_size = 1};
    const SortedClusters s = sort_and_cluster(g.triangles);
    const QueueForest f = run_work_queues(s, 1, 3, process_task_wrong_split);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    size_t differ = 0;
    for (size_t c = 0; c + 1 < s.cluster_begin.size(); ++c) {
        std::vector<uint32_t> expected(f.refs.size(), kUnset);
        reference_range(s.keys, s.cluster_begin[c], s.cluster_begin[c + 1], 2 * (n - 1) + c, 1, expected);
        std::vector<uint32_t> seen(n, 0);
        differ += f.refs[2 * (n - 1) + c] != expected[2 * (n - 1) + c];
        walk(f.refs, f.leaf_runs, expected, f.refs[2 * (n - 1) + c], seen, differ);
    }
    EXPECT_GT(differ, 0u);
    EXPECT_FALSE(same_bvh(build_hlbvh2(g.triangles, options),
                          emit_hlbvh2_forest(g.triangles, options, to_forest(s, f))));
}

TEST(Hlbvh2DeviceLogic, MalformedForestThrows) {
    const SceneGeometry g = test::make_triangle_soup(500, 4, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.2f);
    const SortedClusters s = sort_and_cluster(g.triangles);
    const QueueForest f = run_work_queues(s, 1, 1);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    Hlbvh2Forest bad = to_forest(s, f);
    // A cluster root pointing at a leaf that is not its range's start.
    bad.refs[2 * (n - 1)] = kLeafRef | 1u;
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, BuildOptions{.max_leaf_size = 1}, std::move(bad)), Error);
}

}  // namespace
}  // namespace rf
